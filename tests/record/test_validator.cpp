// Every MCAP file the writer produces is read by an independent implementation: @mcap/core
// (framing, CRCs, indexes, statistics) and @foxglove/omgidl-* (payload decoding with our omgidl
// schema), with values compared against what was written. Skips (with the reason) when node/npm
// are missing or the npm registry cannot be reached.
#include "poise/record/idl_schema.h"
#include "poise/record/mcap.h"
#include "poise/testing/testing.h"
#include "record_test_support.h"

#include <gtest/gtest.h>

namespace poise::record {
namespace {

using testing::ExpectedValue;

struct Counts {
  int imu = 0;
  int attitude = 0;
};

/// Writes IMU (1 kHz) and attitude (100 Hz) messages through WRITER for DURATION_MS of log time;
/// the chunk clock advances with log time. Returns the expected values of the durable messages.
std::vector<ExpectedValue> write_case(McapWriter& w, int64_t& clock_ns, int duration_ms,
                                      Counts& counts) {
  const uint16_t imu_schema =
      w.add_schema("poise::msg::ImuSample", "omgidl",
                   [] { auto t = *flattened_idl("poise::msg::ImuSample"); return std::vector<uint8_t>(t.begin(), t.end()); }());
  const uint16_t att_schema =
      w.add_schema("poise::msg::AttitudeEstimate", "omgidl",
                   [] { auto t = *flattened_idl("poise::msg::AttitudeEstimate"); return std::vector<uint8_t>(t.begin(), t.end()); }());
  const uint16_t imu = w.add_channel(imu_schema, "imu", "cdr",
                                     {{"qos_profile", "sensor"}, {"reliability", "BEST_EFFORT"}});
  const uint16_t att = w.add_channel(att_schema, "attitude/parallel_kf", "cdr",
                                     {{"qos_profile", "estimate"}, {"reliability", "RELIABLE"}});
  std::vector<ExpectedValue> values;
  const int64_t t0 = 1'700'000'000'000'000'000LL;
  for (int ms = 0; ms < duration_ms; ++ms) {
    const int64_t stamp = t0 + ms * 1'000'000LL;
    const uint64_t log_time = static_cast<uint64_t>(stamp + 250'000);
    clock_ns = ms * 1'000'000LL;
    const auto m = testing::make_imu(static_cast<uint32_t>(ms), stamp);
    const auto bytes = testing::serialize<msg::ImuSamplePubSubType>(m);
    w.write(imu, m.header().seq(), log_time, static_cast<uint64_t>(stamp), bytes.data(),
            bytes.size());
    values.push_back({"imu", m.header().seq(), testing::to_json(m), std::to_string(log_time),
                      std::to_string(stamp)});
    ++counts.imu;
    if (ms % 10 == 0) {
      const auto a = testing::make_attitude(static_cast<uint32_t>(ms / 10), stamp);
      const auto abytes = testing::serialize<msg::AttitudeEstimatePubSubType>(a);
      w.write(att, a.header().seq(), log_time, static_cast<uint64_t>(stamp), abytes.data(),
              abytes.size());
      values.push_back({"attitude/parallel_kf", a.header().seq(), testing::to_json(a),
                        std::to_string(log_time), std::to_string(stamp)});
      ++counts.attitude;
    }
  }
  return values;
}

std::string channels_json(const Counts& c) {
  return "{\"imu\":{\"schema\":\"poise::msg::ImuSample\",\"count\":" + std::to_string(c.imu) +
         ",\"metadata\":{\"qos_profile\":\"sensor\"}},\"attitude/parallel_kf\":{\"schema\":"
         "\"poise::msg::AttitudeEstimate\",\"count\":" +
         std::to_string(c.attitude) + "}}";
}

TEST(RecordValidator, IndependentReaderAcceptsEveryWrittenFile) {
  const std::string dir = testing::cases_dir("writer");
  ASSERT_FALSE(dir.empty());
  // Case 1: uncompressed, chunks closed every 100 ms of (injected) clock time.
  {
    int64_t clock_ns = 0;
    WriterOptions opt;
    opt.clock = [&clock_ns] { return clock_ns; };
    opt.max_chunk_duration_ns = 100'000'000;
    Counts counts;
    std::vector<ExpectedValue> values;
    {
      McapWriter w(open_file_sink(dir + "/plain.mcap"), opt);
      values = write_case(w, clock_ns, 1500, counts);
      w.close();
    }
    testing::write_expected(dir + "/plain.mcap", counts.imu + counts.attitude, 10,
                            channels_json(counts), values);
  }
  // Case 2: zstd chunks, size-limited.
  if (zstd_available()) {
    int64_t clock_ns = 0;
    WriterOptions opt;
    opt.clock = [&clock_ns] { return clock_ns; };
    opt.compression = Compression::kZstd;
    opt.chunk_size_bytes = 64 * 1024;
    Counts counts;
    std::vector<ExpectedValue> values;
    {
      McapWriter w(open_file_sink(dir + "/zstd.mcap"), opt);
      values = write_case(w, clock_ns, 1500, counts);
    }
    testing::write_expected(dir + "/zstd.mcap", counts.imu + counts.attitude, 2,
                            channels_json(counts), values);
  }
  // Case 3: the file a write failure (disk full) leaves: finalised with the complete chunks.
  {
    std::vector<uint8_t> buf;
    int64_t clock_ns = 0;
    WriterOptions opt;
    opt.clock = [&clock_ns] { return clock_ns; };
    opt.max_chunk_duration_ns = 100'000'000;
    class Full : public Sink {
     public:
      explicit Full(std::vector<uint8_t>& b) : b_(b) {}
      void write(const uint8_t* d, size_t n) override {
        if (b_.size() + n > 120'000) {
          throw IoError("test sink: No space left on device");
        }
        b_.insert(b_.end(), d, d + n);
      }
      void truncate(uint64_t n) override { b_.resize(static_cast<size_t>(n)); }
      [[nodiscard]] uint64_t position() const override { return b_.size(); }
      [[nodiscard]] std::string name() const override { return "full sink"; }

     private:
      std::vector<uint8_t>& b_;
    };
    Counts counts;
    std::vector<ExpectedValue> values;
    uint64_t durable = 0;
    {
      McapWriter w(std::make_unique<Full>(buf), opt);
      EXPECT_THROW(values = write_case(w, clock_ns, 1500, counts), WriteError);
      durable = w.stats().messages;
    }
    ASSERT_GT(durable, 0u);
    std::ofstream(dir + "/disk_full.mcap", std::ios::binary)
        .write(reinterpret_cast<const char*>(buf.data()), static_cast<std::streamsize>(buf.size()));
    // Which messages survived is checked by the C++ tests; here: framing, CRCs, indexes, decoding.
    testing::write_expected(dir + "/disk_full.mcap", static_cast<int64_t>(durable), 1, "{}", {});
  }
  const auto result = testing::run_node_validator(dir);
  if (!result.skip_reason.empty()) {
    POISE_SKIP(result.skip_reason);
  }
  EXPECT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("files valid"), std::string::npos) << result.output;
  std::printf("%s", result.output.c_str());
}

}  // namespace
}  // namespace poise::record
