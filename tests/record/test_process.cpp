// `poise process`: filters run on a recording offline, deterministically (byte-identical output
// for the same input), input copied through, one estimate per accepted sample, bad payloads
// rejected and counted.
#include "poise/core/attitude.h"

#include <poise/msg/sensor_infoPubSubTypes.h>
#include "poise/process/compare.h"
#include "poise/record/idl_schema.h"
#include "poise/record/mcap.h"
#include "poise/record/replayer.h"
#include "poise/process/process.h"
#include "record_test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <thread>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace poise::record {
namespace {

using namespace std::chrono_literals;
constexpr int kImu = 500;
constexpr int kRejectEvery = 50;
constexpr int kInitAfter = 10;
// The shared message conversion (nodes::to_attitude_msg) normalises the quaternion: a few ulp.
constexpr double kQuatTolerance = 1e-15;
constexpr double kAngleToleranceRad = 1e-12;

/// A deterministic stand-in filter: yaw = 0.01 rad per accepted sample; rejects every 50th
/// sample (by seq) and is initialised after 10 accepted samples.
class FakeFilter : public AttitudeFilter {
 public:
  bool update(const ImuSample& s) override {
    if (s.seq % kRejectEvery == 0) {
      return false;
    }
    ++accepted_;
    return true;
  }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override {
    return quat_from_euler_zyx(0.0, 0.0, 0.01 * accepted_);
  }
  [[nodiscard]] bool initialized() const override { return accepted_ >= kInitAfter; }
  void reset() override { accepted_ = 0; }

 private:
  int accepted_ = 0;
};

/// An AttitudeEstimate message of a recording, deserialised.
bool decode_attitude(const MessageView& m, msg::AttitudeEstimate& e) {
  msg::AttitudeEstimatePubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t p(static_cast<uint32_t>(m.size));
  std::memcpy(p.data, m.data, m.size);
  p.length = static_cast<uint32_t>(m.size);
  return type.deserialize(&p, &e);
}

std::vector<uint8_t> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), {});
}

/// The schema of message type `type` (e.g. "poise::msg::ImuSample"), its IDL flattened.
uint16_t add_idl_schema(McapWriter& w, const char* type) {
  const auto idl = *flattened_idl(type);
  return w.add_schema(type, "omgidl", {idl.begin(), idl.end()});
}

/// A recording being written whose chunk clock is `clock` (set it to each message's time).
struct ClockedRecording {
  explicit ClockedRecording(const std::string& path) : writer(open_file_sink(path), options()) {}
  int64_t clock = 0;
  McapWriter writer;

 private:
  WriterOptions options() {
    WriterOptions o;
    o.clock = [this] { return clock; };
    return o;
  }
};

/// A recording with kImu stationary IMU samples at 100 Hz, attitude messages, one garbage payload
/// at the end (and with `garbage_mid`, one more in the middle).
void write_input(const std::string& path, bool garbage_mid = false, int empty_channels = 0) {
  int64_t clock = 0;
  WriterOptions opt;
  opt.clock = [&clock] { return clock; };
  McapWriter w(open_file_sink(path), opt);
  const uint16_t s = add_idl_schema(w, "poise::msg::ImuSample");
  const uint16_t a = add_idl_schema(w, "poise::msg::AttitudeEstimate");
  const uint16_t imu = w.add_channel(s, "imu", "cdr", {{"qos_profile", "sensor"}});
  const uint16_t att = w.add_channel(a, "attitude/live", "cdr", {});
  for (int i = 0; i < empty_channels; ++i) {  // declared, never written
    (void)w.add_channel(s, "empty/" + std::to_string(i), "cdr", {});
  }
  const int64_t t0 = 5'000'000'000LL;
  for (int i = 0; i < kImu; ++i) {
    const int64_t stamp = t0 + i * 10'000'000LL;
    clock = stamp;
    auto m = testing::make_imu(static_cast<uint32_t>(i), stamp);
    m.accel_mps2(testing::vec3(0.0, 0.0, 9.81));
    m.gyro_rps(testing::vec3(0.0, 0.0, 0.0));
    m.mag_ut(testing::vec3(0.0, 20.0, -40.0));
    m.valid().mag(true);
    const auto bytes = testing::serialize<msg::ImuSamplePubSubType>(m);
    w.write(imu, static_cast<uint32_t>(i), static_cast<uint64_t>(stamp + 1000),
            static_cast<uint64_t>(stamp), bytes.data(), bytes.size());
    if (garbage_mid && i == kImu / 2) {
      const uint8_t bad[8] = {0, 7, 0, 0, 1, 2, 3, 4};  // unknown encapsulation
      w.write(imu, 8888, static_cast<uint64_t>(stamp + 1500), 0, bad, sizeof(bad));
    }
    if (i % 10 == 0) {
      const auto e = testing::serialize<msg::AttitudeEstimatePubSubType>(
          testing::make_attitude(static_cast<uint32_t>(i), stamp));
      w.write(att, static_cast<uint32_t>(i), static_cast<uint64_t>(stamp + 2000),
              static_cast<uint64_t>(stamp), e.data(), e.size());
    }
  }
  const uint8_t garbage[6] = {0, 1, 0, 0, 0xFF, 0xFF};  // CDR header, then too short
  w.write(imu, 9999, static_cast<uint64_t>(t0 + kImu * 10'000'000LL), 0, garbage, sizeof(garbage));
  w.close();
}

TEST(Process, RunsFiltersOfflineDeterministicallyAndCopiesTheInput) {
  const std::string dir = testing::cases_dir("process");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  std::vector<std::vector<uint8_t>> outputs;
  ProcessStats stats;
  for (int run = 0; run < 2; ++run) {
    std::vector<ProcessFilter> filters;
    filters.push_back({"fake", std::make_unique<FakeFilter>(), {}});
    filters.push_back({"fake2", std::make_unique<FakeFilter>(), {}});
    ProcessOptions o;
    o.input = input;
    o.output = dir + "/out" + std::to_string(run) + ".mcap";
    stats = process_recording(o, filters);
    outputs.push_back(read_bytes(o.output));
  }
  // Same input, same filters: byte-identical output.
  ASSERT_FALSE(outputs[0].empty());
  EXPECT_EQ(outputs[0], outputs[1]);
  // Counts: every input message, bad payload rejected and counted, rejections per filter.
  EXPECT_EQ(stats.input_messages, static_cast<uint64_t>(kImu + kImu / 10 + 1));
  EXPECT_EQ(stats.imu_samples, static_cast<uint64_t>(kImu + 1));
  EXPECT_EQ(stats.undecodable, 1u);
  EXPECT_EQ(stats.rejected["fake"], static_cast<uint64_t>(kImu / kRejectEvery));
  const uint64_t accepted = kImu - kImu / kRejectEvery;
  EXPECT_EQ(stats.estimates["fake"], accepted - (kInitAfter - 1));
  // The output: input copied through; one estimate per accepted, initialised sample, with the
  // filter's attitude and the sample's stamp.
  const McapReader out = McapReader::open_file(dir + "/out0.mcap");
  ASSERT_TRUE(out.report().complete);
  std::map<std::string, uint64_t> per_topic;
  int accepted_so_far = kInitAfter - 1;
  MessageCursor cursor = out.messages();
  while (const MessageView* m = cursor.next()) {
    ++per_topic[m->channel->topic];
    if (m->channel->topic == "processed/attitude/fake") {
      msg::AttitudeEstimate e;
      ASSERT_TRUE(decode_attitude(*m, e));
      ++accepted_so_far;
      const Eigen::Quaterniond want = quat_from_euler_zyx(0.0, 0.0, 0.01 * accepted_so_far);
      EXPECT_NEAR(e.q_world_body().w(), want.w(), kQuatTolerance);
      EXPECT_NEAR(e.q_world_body().z(), want.z(), kQuatTolerance);
      EXPECT_NEAR(e.yaw_rad(), euler_zyx_from_quat(want).z(), kAngleToleranceRad);
      EXPECT_EQ(m->publish_time_ns, static_cast<uint64_t>(e.header().stamp_ns()));
      EXPECT_EQ(e.filter_id().to_string(), "fake");
      EXPECT_EQ(e.sensor_id().to_string(), "fake");  // a filter alone is its own instance
      // the input sample's seq (write_input: stamp = 5 s + seq * 10 ms)
      EXPECT_EQ(e.header().stamp_ns(), 5'000'000'000LL + static_cast<int64_t>(e.header().seq()) * 10'000'000LL);
    }
  }
  EXPECT_EQ(per_topic["imu"], static_cast<uint64_t>(kImu + 1));
  EXPECT_EQ(per_topic["attitude/live"], static_cast<uint64_t>(kImu / 10));
  EXPECT_EQ(per_topic["processed/attitude/fake"], stats.estimates["fake"]);
  EXPECT_EQ(per_topic["processed/attitude/fake2"], stats.estimates["fake2"]);
  // The processed file is a valid MCAP for the independent reader too.
  testing::write_expected(dir + "/out0.mcap", static_cast<int64_t>(out.report().messages), 1,
                          "{\"processed/attitude/fake\":{\"schema\":\"poise::msg::AttitudeEstimate\","
                          "\"count\":" + std::to_string(stats.estimates["fake"]) + "}}",
                          {}, {"imu/9999"});
  std::remove((dir + "/out1.mcap").c_str());
  const auto validation = testing::run_node_validator(dir);
  if (validation.skip_reason.empty()) {
    EXPECT_EQ(validation.exit_code, 0) << validation.output;
  } else {
    std::printf("independent validation not run: %s\n", validation.skip_reason.c_str());
  }
}

/// Records the stamps of the samples it is given, in the order it is given them.
class OrderFilter : public AttitudeFilter {
 public:
  explicit OrderFilter(std::vector<int64_t>* seen) : seen_(seen) {}
  bool update(const ImuSample& s) override {
    seen_->push_back(s.stamp_ns);
    return true;
  }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override { return Eigen::Quaterniond::Identity(); }
  [[nodiscard]] bool initialized() const override { return true; }
  void reset() override {}

 private:
  std::vector<int64_t>* seen_;
};

TEST(Process, GivenSamplesOutOfStampOrderWhenProcessedThenTheyRunInStampOrderHoldingOnlyTheirDisplacement) {
  // 300 IMU samples at 100 Hz; every 50th is written kDelay messages late (as a vision pose
  // arrives after the IMU samples taken after its capture). Oracle: stamp order is increasing
  // stamps; the farthest any sample sits after its place in that order is kDelay.
  constexpr int kSamples = 300;
  constexpr int kDelay = 7;
  const std::string dir = testing::cases_dir("process_order");
  const std::string input = dir + "/input.mcap";
  {
    int64_t clock = 0;
    WriterOptions opt;
    opt.clock = [&clock] { return clock; };
    McapWriter w(open_file_sink(input), opt);
    const auto idl = *flattened_idl("poise::msg::ImuSample");
    const uint16_t s = w.add_schema("poise::msg::ImuSample", "omgidl", {idl.begin(), idl.end()});
    const uint16_t imu = w.add_channel(s, "imu", "cdr", {});
    std::vector<int> file_order;
    for (int i = 0; i < kSamples; ++i) {
      if (i % 50 == 10) {
        continue;  // written kDelay positions later
      }
      file_order.push_back(i);
      if (i % 50 == 10 + kDelay) {
        file_order.push_back(i - kDelay);
      }
    }
    ASSERT_EQ(file_order.size(), static_cast<size_t>(kSamples));
    uint64_t log_ns = 1'000'000'000ULL;
    for (int i : file_order) {
      const int64_t stamp = 5'000'000'000LL + i * 10'000'000LL;
      clock = static_cast<int64_t>(log_ns);
      auto m = testing::make_imu(static_cast<uint32_t>(i), stamp);
      m.accel_mps2(testing::vec3(0.0, 0.0, 9.81));
      const auto bytes = testing::serialize<msg::ImuSamplePubSubType>(m);
      w.write(imu, static_cast<uint32_t>(i), log_ns, static_cast<uint64_t>(stamp), bytes.data(), bytes.size());
      log_ns += 10'000'000ULL;  // arrival order = file order
    }
    w.close();
  }
  for (const ProcessOrder order : {ProcessOrder::kStamp, ProcessOrder::kRecorded}) {
    std::vector<int64_t> seen;
    std::vector<ProcessFilter> filters;
    filters.push_back({"order", std::make_unique<OrderFilter>(&seen), {}});
    ProcessOptions o;
    o.input = input;
    o.output = dir + "/out.mcap";
    o.order = order;
    const ProcessStats stats = process_recording(o, filters);
    ASSERT_EQ(seen.size(), static_cast<size_t>(kSamples));
    if (order == ProcessOrder::kStamp) {
      EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
      EXPECT_EQ(stats.reorder_window, static_cast<uint64_t>(kDelay));
    } else {
      EXPECT_FALSE(std::is_sorted(seen.begin(), seen.end()));
      EXPECT_EQ(stats.reorder_window, 0u);
    }
    EXPECT_EQ(stats.estimates.at("order"), static_cast<uint64_t>(kSamples));
    // every estimate follows the input message it was computed from
    const McapReader out = McapReader::open_file(o.output);
    int64_t last_input_stamp = -1;
    MessageCursor cursor = out.messages();
    uint64_t estimates = 0;
    while (const MessageView* m = cursor.next()) {
      if (m->channel->topic == "imu") {
        last_input_stamp = static_cast<int64_t>(m->publish_time_ns);
      } else if (m->channel->topic == "processed/attitude/order") {
        ++estimates;
        EXPECT_EQ(static_cast<int64_t>(m->publish_time_ns), last_input_stamp);
      }
    }
    EXPECT_EQ(estimates, static_cast<uint64_t>(kSamples));
  }
}

TEST(Process, CliRunsRealFiltersFromAHostFileAndIsReproducible) {
  const std::string dir = testing::cases_dir("process-cli");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  const std::string host = dir + "/host.yaml";
  std::ofstream(host) << "components:\n"
                         "  - type: imu_driver\n    name: imu0\n"
                         "  - type: parallel_kf\n    name: pkf\n"
                         "  - type: gauss_newton\n    name: gn\n";
  std::vector<std::vector<uint8_t>> outputs;
  for (int run = 0; run < 2; ++run) {
    const std::string out = dir + "/cli" + std::to_string(run) + ".mcap";
    const auto r = poise::testing::run({std::string(POISE_RECORD_TOOL), "process", input, "-o", out,
                                        "--host", host},
                                       60s);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("component 'imu0' (imu_driver) is not an estimator: skipped"),
              std::string::npos)
        << r.output;
    // (progress is printed only for work over 2 s: Progress.* tests it)
    outputs.push_back(read_bytes(out));
  }
  EXPECT_EQ(outputs[0], outputs[1]);
  const McapReader out = McapReader::open_file(dir + "/cli0.mcap");
  std::set<std::string> topics;
  for (const auto& [id, c] : out.channels()) {
    topics.insert(c.topic);
  }
  // the live topics of the components under processed/ (sensor_id = the instance name)
  EXPECT_EQ(topics.count("processed/attitude/parallel_kf"), 1u);
  EXPECT_EQ(topics.count("processed/attitude/gauss_newton"), 1u);
  EXPECT_EQ(topics.count("processed/diagnostics"), 1u);
  // Unknown filter names are a clear error.
  const auto bad = poise::testing::run({std::string(POISE_RECORD_TOOL), "process", input, "-o",
                                        dir + "/bad.mcap", "--filter", "no_such_filter"},
                                       60s);
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("no_such_filter"), std::string::npos) << bad.output;
}

/// Every AttitudeEstimate on `topic` of an MCAP file, in file order.
std::vector<msg::AttitudeEstimate> read_attitudes(const std::string& path, const std::string& topic) {
  std::vector<msg::AttitudeEstimate> out;
  const McapReader reader = McapReader::open_file(path);
  MessageCursor cursor = reader.messages();
  while (const MessageView* m = cursor.next()) {
    if (m->channel->topic == topic) {
      out.emplace_back();
      EXPECT_TRUE(decode_attitude(*m, out.back()));
    }
  }
  return out;
}

// Issue 20, true north everywhere a filter runs: `process --filter` takes the north keys through
// --set (KEY=VALUE for every --filter filter, NAME.KEY=VALUE for one). Oracle: the conventions'
// yaw_true = yaw_magnetic - D applied to the same filter's run without a declination.
TEST(Process, GivenADeclinationForAFilterThenItsHeadingTurnsByItAndItsFrameIsEnuTrue) {
  constexpr double kDeclinationDeg = 10.0;
  constexpr double kTurnTolRad = 1e-9;  // one rotation about z of the same filter's output
  const std::string dir = testing::cases_dir("process-north");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  const std::string topic = "processed/attitude/parallel_kf";
  auto process = [&](const std::string& out, const std::vector<std::string>& extra) {
    std::vector<std::string> argv{std::string(POISE_RECORD_TOOL), "process", input, "-o", out, "--filter",
                                  "parallel_kf", "--no-compare"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return poise::testing::run(argv, 60s);
  };
  const auto magnetic = process(dir + "/magnetic.mcap", {});
  ASSERT_EQ(magnetic.exit_code, 0) << magnetic.output;
  const auto every = process(dir + "/true.mcap", {"--set", "declination_deg=10"});
  ASSERT_EQ(every.exit_code, 0) << every.output;
  const auto named = process(dir + "/true_named.mcap", {"--set", "parallel_kf.declination_deg=10"});
  ASSERT_EQ(named.exit_code, 0) << named.output;
  EXPECT_NE(every.output.find("parallel_kf (--filter, enu_true)"), std::string::npos) << every.output;

  const auto m = read_attitudes(dir + "/magnetic.mcap", topic);
  const auto t = read_attitudes(dir + "/true.mcap", topic);
  ASSERT_GT(m.size(), 400U);
  ASSERT_EQ(t.size(), m.size());
  EXPECT_EQ(read_bytes(dir + "/true.mcap"), read_bytes(dir + "/true_named.mcap")) << "both spellings";
  for (std::size_t i = 0; i < m.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(m[i].header().frame_id().to_string(), "enu_magnetic");
    EXPECT_EQ(t[i].header().frame_id().to_string(), "enu_true");
    EXPECT_EQ(t[i].header().seq(), m[i].header().seq());
    EXPECT_NEAR(std::remainder(t[i].yaw_rad() - (m[i].yaw_rad() - kDeclinationDeg * kRadPerDeg), 2.0 * kPi), 0.0,
                kTurnTolRad);
    EXPECT_NEAR(t[i].roll_rad(), m[i].roll_rad(), kTurnTolRad);
    EXPECT_NEAR(t[i].pitch_rad(), m[i].pitch_rad(), kTurnTolRad);
    const Eigen::Quaterniond qm(m[i].q_world_body().w(), m[i].q_world_body().x(), m[i].q_world_body().y(),
                                m[i].q_world_body().z());
    const Eigen::Quaterniond qt(t[i].q_world_body().w(), t[i].q_world_body().x(), t[i].q_world_body().y(),
                                t[i].q_world_body().z());
    EXPECT_NEAR(quat_angle_between(qt, qm), kDeclinationDeg * kRadPerDeg, kTurnTolRad);
  }
  // a filter parameter is not a north key: it belongs in the filter's YAML (NAME=CONFIG.yaml)
  const auto param = process(dir + "/bad.mcap", {"--set", "sigma_mag_ut=1"});
  EXPECT_EQ(param.exit_code, 2) << param.output;
  EXPECT_NE(param.output.find("unknown key 'sigma_mag_ut' (known: declination_deg"), std::string::npos) << param.output;
  // without a --filter, KEY=VALUE has nothing to apply to
  const auto none = poise::testing::run({std::string(POISE_RECORD_TOOL), "process", input, "-o", dir + "/none.mcap",
                                         "--set", "declination_deg=10"},
                                        60s);
  EXPECT_EQ(none.exit_code, 2) << none.output;
  EXPECT_NE(none.output.find("applies to the --filter filters"), std::string::npos) << none.output;
}

// `process --filter` follows one IMU, as a live node does (issue 31's "noticed": imu_sensor_id was
// a host-file parameter only). Two stationary IMUs interleaved on `imu`: imu0's field lies along
// body y (yaw 0 in ENU: y points north), imu1's along body x (x points north: yaw +90 deg). Oracle:
// that geometry; a filter that fused both would sit between them or jump.
TEST(Process, GivenTwoImusOnOneTopicWhenAFilterIsToldWhichToFollowThenItRunsOnlyThatOne) {
  constexpr int kPerImu = 300;
  constexpr double kYawTolDeg = 1.0;  // noise-free samples: the field's heading, to the filter's convergence
  const std::string dir = testing::cases_dir("process-imu-id");
  const std::string input = dir + "/input.mcap";
  {
    ClockedRecording r(input);
    const uint16_t s = add_idl_schema(r.writer, "poise::msg::ImuSample");
    const uint16_t imu = r.writer.add_channel(s, "imu", "cdr", {{"qos_profile", "sensor"}});
    for (int i = 0; i < kPerImu; ++i) {
      for (int k = 0; k < 2; ++k) {
        const int64_t stamp = 1'000'000'000LL + i * 10'000'000LL + k * 5'000'000LL;
        r.clock = stamp;
        auto m = testing::make_imu(static_cast<uint32_t>(i), stamp);
        m.sensor_id(k == 0 ? "imu0" : "imu1");
        m.accel_mps2(testing::vec3(0.0, 0.0, 9.81));
        m.gyro_rps(testing::vec3(0.0, 0.0, 0.0));
        m.mag_ut(k == 0 ? testing::vec3(0.0, 20.0, -40.0) : testing::vec3(20.0, 0.0, -40.0));
        m.valid().mag(true);
        const auto bytes = testing::serialize<msg::ImuSamplePubSubType>(m);
        r.writer.write(imu, static_cast<uint32_t>(2 * i + k), static_cast<uint64_t>(stamp + 1000),
                       static_cast<uint64_t>(stamp), bytes.data(), bytes.size());
      }
    }
    r.writer.close();
  }
  auto process = [&](const std::string& out, const std::vector<std::string>& extra) {
    std::vector<std::string> argv{std::string(POISE_RECORD_TOOL), "process", input, "-o", dir + "/" + out,
                                  "--filter", "parallel_kf", "--no-compare"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return poise::testing::run(argv, 60s);
  };
  const auto yaws_deg = [&](const std::string& out) {
    std::vector<double> y;
    for (const auto& e : read_attitudes(dir + "/" + out, "processed/attitude/parallel_kf")) {
      y.push_back(e.yaw_rad() / kRadPerDeg);
    }
    return y;
  };
  const struct {
    const char* out;
    std::vector<std::string> extra;
    double yaw_deg;
    const char* followed;
  } cases[] = {{"first.mcap", {}, 0.0, "imu0"},  // the first one heard
               {"imu1.mcap", {"--set", "imu_sensor_id=imu1"}, 90.0, "imu1"},
               {"imu1_named.mcap", {"--set", "parallel_kf.imu_sensor_id=imu1"}, 90.0, "imu1"}};
  for (const auto& c : cases) {
    SCOPED_TRACE(c.out);
    const auto r = process(c.out, c.extra);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find(std::to_string(kPerImu) + " sample(s) of other IMUs"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("followed IMU '" + std::string(c.followed) + "'"), std::string::npos) << r.output;
    const std::vector<double> y = yaws_deg(c.out);
    ASSERT_GT(y.size(), static_cast<size_t>(kPerImu) * 9 / 10);
    ASSERT_LE(y.size(), static_cast<size_t>(kPerImu)) << "one estimate per sample of the followed IMU";
    for (double v : y) {
      ASSERT_NEAR(v, c.yaw_deg, kYawTolDeg);
    }
  }
  // hostile values are refused as a host file's are, naming the key; a key given twice too
  const auto too_long = process("bad1.mcap", {"--set", "imu_sensor_id=" + std::string(300, 'x')});
  EXPECT_EQ(too_long.exit_code, 2) << too_long.output;
  EXPECT_NE(too_long.output.find("imu_sensor_id"), std::string::npos) << too_long.output;
  const auto twice = process("bad2.mcap", {"--set", "imu_sensor_id=imu0", "--set", "parallel_kf.imu_sensor_id=imu1"});
  EXPECT_EQ(twice.exit_code, 2) << twice.output;
  EXPECT_NE(twice.output.find("given twice"), std::string::npos) << twice.output;
}

// A selective_ekf component runs as its live node does: attitude, pose and diagnostics, with the
// host's parameters (an unknown one is refused as the node refuses it); --set changes one.
TEST(Process, SelectiveEkfComponentPublishesWhatItsLiveNodePublishes) {
  const std::string dir = testing::cases_dir("process-selective");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  const std::string host = dir + "/host.yaml";
  std::ofstream(host) << "components:\n"
                         "  - type: selective_ekf\n    name: sekf\n    params: {imu_delay_s: 0.004, diagnostics_every: 1}\n";
  const std::string out = dir + "/out.mcap";
  const auto r = poise::testing::run({poise::testing::bin("poise"), "process", input, "-o", out, "--host", host}, 60s);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("comparison:"), std::string::npos) << r.output;
  const McapReader reader = McapReader::open_file(out);
  std::map<std::string, uint64_t> per_topic;
  MessageCursor cursor = reader.messages();
  while (const MessageView* m = cursor.next()) {
    ++per_topic[m->channel->topic];
  }
  EXPECT_GT(per_topic["processed/attitude/selective_ekf"], 0u);
  EXPECT_EQ(per_topic["processed/pose/selective_ekf"], per_topic["processed/attitude/selective_ekf"]);
  EXPECT_EQ(per_topic["processed/diagnostics"], static_cast<uint64_t>(kImu));  // diagnostics_every 1: one per valid sample
  const auto bad = poise::testing::run({poise::testing::bin("poise"), "process", input, "-o",
                                        dir + "/bad.mcap", "--host", host, "--set", "sekf.no_such_key=1"},
                                       60s);
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("no_such_key"), std::string::npos) << bad.output;
  const auto unknown = poise::testing::run({poise::testing::bin("poise"), "process", input, "-o",
                                            dir + "/bad.mcap", "--host", host, "--set", "nobody.imu_delay_s=0"},
                                           60s);
  EXPECT_EQ(unknown.exit_code, 2) << unknown.output;
  EXPECT_NE(unknown.output.find("no component named 'nobody'"), std::string::npos) << unknown.output;
  const auto changed = poise::testing::run({poise::testing::bin("poise"), "process", input, "-o",
                                            dir + "/changed.mcap", "--host", host, "--set",
                                            "sekf.imu_delay_s=0.02"},
                                           60s);
  EXPECT_EQ(changed.exit_code, 0) << changed.output;
}

// The comparison `poise process` prints, against an oracle written by hand: live yaw 0, truth
// yaw 0.5 deg, processed yaw 1 deg (2 deg at seq 7); the processed magnetometer untrusted at
// seq 3, 4 and 8, vision fused only by the processed filter at seq 5; a live estimate (seq 10)
// without a processed one; samples every 10 ms.
/// A file of AttitudeEstimate channels <live_topic>, processed/<live_topic> and truth/attitude,
/// its chunk clock at `*clock`.
struct AttitudeFile {
  AttitudeFile(const std::string& path, const std::string& live_topic, int64_t* clock)
      : w(open_file_sink(path), options(clock)) {
    const auto idl = *flattened_idl("poise::msg::AttitudeEstimate");
    const uint16_t schema = w.add_schema("poise::msg::AttitudeEstimate", "omgidl", {idl.begin(), idl.end()});
    live = w.add_channel(schema, live_topic, "cdr", {});
    processed = w.add_channel(schema, "processed/" + live_topic, "cdr", {});
    truth = w.add_channel(schema, "truth/attitude", "cdr", {});
  }
  static WriterOptions options(int64_t* clock) {
    WriterOptions opt;
    opt.clock = [clock] { return *clock; };
    return opt;
  }
  McapWriter w;
  uint16_t live = 0;
  uint16_t processed = 0;
  uint16_t truth = 0;
};

/// Estimates at `step_ns` apart with known differences; times in the expectations scale with it.
void check_known_differences(int64_t step_ns) {
  constexpr double kDegTolerance = 1e-9;  // angles through quaternions and back, deg
  constexpr double kSecondsTolerance = 1e-12;
  const double k = static_cast<double>(step_ns) / 1e7;  // the expectations below are for 10 ms
  SCOPED_TRACE(::testing::Message() << "step " << step_ns << " ns");
  const std::string dir = testing::cases_dir("compare");
  const std::string path = dir + "/compare_" + std::to_string(step_ns) + ".mcap";
  {
    int64_t clock = 0;
    AttitudeFile file(path, "attitude/selective_ekf", &clock);
    McapWriter& w = file.w;
    const uint16_t live = file.live;
    const uint16_t processed = file.processed;
    const uint16_t truth = file.truth;
    auto put = [&](uint16_t channel, uint32_t seq, double yaw_deg, bool mag, uint32_t sources) {
      const int64_t stamp = 7'000'000'000LL + static_cast<int64_t>(seq) * step_ns;
      clock = stamp;
      auto m = testing::make_attitude(seq, stamp);
      m.sensor_id(channel == truth ? "sim" : "sekf");
      const Eigen::Quaterniond q = quat_from_euler_zyx(0.0, 0.0, yaw_deg * kRadPerDeg);
      m.q_world_body().w(q.w());
      m.q_world_body().x(q.x());
      m.q_world_body().y(q.y());
      m.q_world_body().z(q.z());
      m.mag_trusted(mag);
      m.sources_fused(sources);
      const auto bytes = testing::serialize<msg::AttitudeEstimatePubSubType>(m);
      w.write(channel, seq, static_cast<uint64_t>(stamp), static_cast<uint64_t>(stamp), bytes.data(),
              bytes.size());
    };
    for (uint32_t i = 0; i <= 10; ++i) {
      put(truth, i, 0.5, true, 0);
      put(live, i, 0.0, true, msg::SOURCE_GYRO);
      if (i < 10) {
        put(processed, i, i == 7 ? 2.0 : 1.0, i != 3 && i != 4 && i != 8,
            msg::SOURCE_GYRO | (i == 5 ? msg::SOURCE_VISION : 0U));
      }
    }
    w.close();
  }
  const std::vector<SeriesComparison> all = compare_processed(path);
  ASSERT_EQ(all.size(), 1U) << format_comparison(all);
  const SeriesComparison& c = all[0];
  EXPECT_EQ(c.topic, "attitude/selective_ekf");
  EXPECT_EQ(c.sensor_id, "sekf");
  EXPECT_EQ(c.processed, 10U);
  EXPECT_EQ(c.live, 11U);
  EXPECT_EQ(c.matched, 10U);
  EXPECT_NEAR(c.rmse, std::sqrt((9.0 * 1.0 + 4.0) / 10.0), kDegTolerance);
  EXPECT_NEAR(c.largest, 2.0, kDegTolerance);
  EXPECT_NEAR(c.largest_at_s, 0.07 * k, kSecondsTolerance * k);
  EXPECT_EQ(c.truth_topic, "truth/attitude");
  EXPECT_NEAR(c.processed_truth_rmse, std::sqrt((9.0 * 0.25 + 2.25) / 10.0), kDegTolerance);
  EXPECT_NEAR(c.live_truth_rmse, 0.5, kDegTolerance);
  EXPECT_EQ(c.mag_trust.processed_yes, 7U);
  EXPECT_EQ(c.mag_trust.live_yes, 10U);
  EXPECT_EQ(c.mag_trust.processed_only, 0U);
  EXPECT_EQ(c.mag_trust.live_only, 3U);
  ASSERT_EQ(c.mag_trust.intervals.size(), 2U);
  EXPECT_NEAR(c.mag_trust.intervals[0].start_s, 0.03 * k, kSecondsTolerance * k);
  EXPECT_NEAR(c.mag_trust.intervals[0].end_s, 0.04 * k, kSecondsTolerance * k);
  EXPECT_EQ(c.mag_trust.intervals[0].samples, 2U);
  EXPECT_NEAR(c.mag_trust.intervals[1].start_s, 0.08 * k, kSecondsTolerance * k);
  EXPECT_EQ(c.vision_fused.processed_only, 1U);
  EXPECT_EQ(c.vision_fused.live_only, 0U);
  ASSERT_EQ(c.vision_fused.intervals.size(), 1U);
  EXPECT_NEAR(c.vision_fused.intervals[0].start_s, 0.05 * k, kSecondsTolerance * k);
  const std::string text = format_comparison(all);
  if (step_ns == 10'000'000LL) {
    EXPECT_NE(text.find("0.03-0.04 s 0.08-0.08 s"), std::string::npos) << text;
  }
  EXPECT_NE(text.find("1 live estimate(s) without a processed one"), std::string::npos) << text;
  // A window (`poise process --window`) scores only the processed estimates inside it: seq 5-8,
  // whose errors against truth are 0.5, 0.5, 1.5 and 0.5 deg of yaw.
  const CompareWindow window{0.045 * k, 0.085 * k};
  const std::vector<SeriesComparison> windowed = compare_processed(path, "processed/", window);
  ASSERT_EQ(windowed.size(), 1U);
  EXPECT_EQ(windowed[0].in_window.samples, 4U);
  EXPECT_NEAR(windowed[0].in_window.heading_rmse, std::sqrt(3.0 / 4.0), kDegTolerance);
  EXPECT_NEAR(windowed[0].in_window.rmse, std::sqrt(3.0 / 4.0), kDegTolerance);
  EXPECT_NE(format_comparison(windowed).find("(4 samples): RMSE 0.866 deg, heading RMSE 0.866 deg"),
            std::string::npos)
      << format_comparison(windowed);
  EXPECT_EQ(all[0].in_window.samples, 0U) << "no window given: nothing scored in one";
}

TEST(Compare, GivenKnownDifferencesThenRmseLargestAndTrustIntervalsAreExact) {
  check_known_differences(10'000'000LL);  // 0.1 s in all
}

TEST(Compare, GivenEstimatesSpanningSeveralComparisonHorizonsThenTheFiguresAreTheSame) {
  check_known_differences(4'000'000'000LL);  // 40 s in all: compared in several 10 s windows
}

TEST(Compare, GivenStampsAtTheEndsOfInt64WhenComparedThenEveryEstimateIsCountedAndNothingOverflows) {
  // Stamps come from the file: the comparison's time arithmetic must stay inside int64_t (a
  // sanitizer build turns an overflow into a failure) and count every estimate.
  const std::string dir = testing::cases_dir("compare_hostile");
  const std::string path = dir + "/hostile.mcap";
  const int64_t stamps[] = {std::numeric_limits<int64_t>::min() + 1, -5, 0, 7'000'000'000LL,
                            std::numeric_limits<int64_t>::max() - 1, std::numeric_limits<int64_t>::max()};
  {
    int64_t clock = 0;
    AttitudeFile file(path, "attitude/x", &clock);
    McapWriter& w = file.w;
    const uint16_t live = file.live;
    const uint16_t processed = file.processed;
    const uint16_t truth = file.truth;
    uint32_t seq = 0;
    for (const int64_t stamp : stamps) {
      for (const uint16_t channel : {truth, live, processed}) {
        auto m = testing::make_attitude(seq, stamp);
        m.sensor_id(channel == truth ? "sim" : "x");
        const auto bytes = testing::serialize<msg::AttitudeEstimatePubSubType>(m);
        w.write(channel, seq, static_cast<uint64_t>(seq), 0, bytes.data(), bytes.size());
      }
      ++seq;
    }
    w.close();
  }
  const std::vector<SeriesComparison> all = compare_processed(path);
  ASSERT_EQ(all.size(), 1U) << format_comparison(all);
  EXPECT_EQ(all[0].processed, std::size(stamps));
  EXPECT_EQ(all[0].live, std::size(stamps));
  EXPECT_EQ(all[0].matched, std::size(stamps));
  EXPECT_EQ(all[0].rmse, 0.0);
}

/// Flips one byte inside the records of chunk `k` of `path` (its CRC no longer matches); returns
/// the messages that chunk held.
uint64_t damage_chunk(const std::string& path, size_t k) {
  uint64_t offset = 0;
  uint64_t length = 0;
  uint64_t held = 0;
  {
    const McapReader r = McapReader::open_file(path);
    EXPECT_GT(r.chunks().size(), k + 1);
    offset = r.chunks()[k].offset;
    length = r.chunks()[k].length;
    MessageCursor cursor = r.messages();
    while (const MessageView* m = cursor.next()) {
      held += m->chunk_offset == offset ? 1 : 0;
    }
  }
  std::vector<uint8_t> bytes = read_bytes(path);
  bytes[offset + length - 5] ^= 0x40;
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  return held;
}

// Issue 19 item 6: an unreadable chunk is skipped, counted and reported, and the command exits 3
// unless --allow-damaged; a malformed payload is skipped and named by index and offset.
TEST(Process, GivenACorruptChunkWhenProcessedThenTheRestIsProcessedAndTheDamageReported) {
  const std::string dir = testing::cases_dir("process-damaged");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  const uint64_t lost = damage_chunk(input, 1);
  ASSERT_GT(lost, 0u);
  std::vector<ProcessFilter> filters;
  filters.push_back({"fake", std::make_unique<FakeFilter>(), {}});
  ProcessOptions o;
  o.input = input;
  o.output = dir + "/out.mcap";
  const ProcessStats stats = process_recording(o, filters);
  EXPECT_EQ(stats.damaged_chunks, 1u);
  EXPECT_TRUE(stats.input_damaged());
  EXPECT_EQ(stats.input_messages, static_cast<uint64_t>(kImu + kImu / 10 + 1) - lost);
  EXPECT_EQ(stats.undecodable, 1u);
  ASSERT_EQ(stats.undecodable_details.size(), 1u);
  // The garbage payload is the last message: #(messages read), in the last chunk.
  EXPECT_NE(stats.undecodable_details[0].find("message #" + std::to_string(stats.input_messages) +
                                              " (log time "),
            std::string::npos)
      << stats.undecodable_details[0];
  EXPECT_NE(stats.undecodable_details[0].find("chunk at byte "), std::string::npos);
  EXPECT_NE(stats.undecodable_details[0].find("6 bytes: payload truncated"), std::string::npos)
      << stats.undecodable_details[0];

  const std::string out = dir + "/cli.mcap";
  const auto r = poise::testing::run(
      {poise::testing::bin("poise"), "process", input, "-o", out, "--filter", "parallel_kf"}, 60s);
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("the input is damaged (1 corrupt part(s) skipped)"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("chunk CRC mismatch"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("skipped message #"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--allow-damaged"), std::string::npos) << r.output;
  EXPECT_TRUE(McapReader::open_file(out).report().complete) << "the output is still finalised";
  const auto allowed = poise::testing::run({poise::testing::bin("poise"), "process", input, "-o",
                                            out, "--filter", "parallel_kf", "--allow-damaged"},
                                           60s);
  EXPECT_EQ(allowed.exit_code, 0) << allowed.output;
}

TEST(Replay, GivenACorruptChunkAndAMalformedPayloadWhenReplayedThenEveryReadableValidMessageGoesOut) {
  const std::string dir = testing::cases_dir("replay-damaged");
  const std::string input = dir + "/input.mcap";
  write_input(input, true);
  const uint64_t lost = damage_chunk(input, 1);
  poise::testing::DomainLease lease;
  const std::vector<std::string> env = {"POISE_DDS_PROFILE=poise_loopback"};
  const std::vector<std::string> argv = {poise::testing::bin("poise"), "replay", input,
                                         "--as-fast-as-possible", "--wait", "0", "--domain",
                                         std::to_string(lease.id())};
  const auto r = poise::testing::run(argv, 60s, env);
  EXPECT_EQ(r.exit_code, 3) << r.output;
  const uint64_t readable = static_cast<uint64_t>(kImu + kImu / 10 + 2) - lost;
  // Every readable message except the two malformed payloads is published: the one in the middle
  // does not stop the replay.
  EXPECT_NE(r.output.find("published " + std::to_string(readable - 2) + " messages"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("poise replay: skipped message #" + std::to_string(readable) +
                          " (log time "),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("on 'imu', 8 bytes: unsupported encapsulation 0x0007"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("skipped 2 malformed payload(s)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("chunk CRC mismatch"), std::string::npos) << r.output;
  std::vector<std::string> allowed = argv;
  allowed.emplace_back("--allow-damaged");
  const auto ok = poise::testing::run(allowed, 60s, env);
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
}

// Issue 33: `replay` and `process` exited 0 on a file cut short (a killed recorder) although their
// help says 3 without --allow-damaged. Oracle: the documented exit codes; the readable part is
// still used either way.
TEST(Process, GivenARecordingCutShortWhenProcessedOrReplayedThenExit3UnlessDamageIsAllowed) {
  const std::string dir = testing::cases_dir("process-cut");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  std::filesystem::resize_file(input, std::filesystem::file_size(input) * 6 / 10);
  ASSERT_FALSE(McapReader::open_file(input).report().complete);
  const std::string out = dir + "/out.mcap";
  const std::vector<std::string> process = {poise::testing::bin("poise"), "process", input, "-o", out,
                                            "--filter", "parallel_kf"};
  const auto r = poise::testing::run(process, 60s);
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("the input is incomplete"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("exit code 3: the input is damaged or incomplete (see above); --allow-damaged accepts it"),
            std::string::npos)
      << r.output;
  std::vector<std::string> allowed = process;
  allowed.emplace_back("--allow-damaged");
  EXPECT_EQ(poise::testing::run(allowed, 60s).exit_code, 0);

  poise::testing::DomainLease lease;
  const std::vector<std::string> env = {"POISE_DDS_PROFILE=poise_loopback"};
  const std::vector<std::string> replay = {poise::testing::bin("poise"), "replay", input, "--as-fast-as-possible",
                                           "--wait", "0", "--domain", std::to_string(lease.id())};
  const auto rr = poise::testing::run(replay, 60s, env);
  EXPECT_EQ(rr.exit_code, 3) << rr.output;
  EXPECT_NE(rr.output.find("the file was incomplete"), std::string::npos) << rr.output;
  std::vector<std::string> replay_allowed = replay;
  replay_allowed.emplace_back("--allow-damaged");
  EXPECT_EQ(poise::testing::run(replay_allowed, 60s, env).exit_code, 0);
}

/// Replay options for `input` on `domain` (loopback), as fast as possible, not waiting for
/// subscribers, logging to `log`.
ReplayOptions fast_replay(const std::string& input, int domain, std::ostringstream& log) {
  ReplayOptions o;
  o.input = input;
  o.domain = domain;
  o.participant_profile = "poise_loopback";
  o.wait_for_subscribers_s = 0.0;
  o.schedule.as_fast_as_possible = true;
  o.log = &log;
  return o;
}

// Issue 33: `replay` made a DDS writer (~90 KB) for every declared channel, so a file declaring
// 65535 channels ended in std::bad_alloc. Writers are made for channels that carry messages and at
// most max_writers of them; the messages beyond are counted. Oracle: the file's own layout (2
// channels with messages, 2000 without; 50 attitude messages).
TEST(Replay, GivenAFileDeclaringManyChannelsWhenReplayedThenOnlyChannelsWithMessagesGetAWriterWithinTheLimit) {
  const std::string dir = testing::cases_dir("replay-channels");
  const std::string input = dir + "/input.mcap";
  write_input(input, false, 2000);
  poise::testing::DomainLease lease;
  std::ostringstream log;
  ReplayOptions o = fast_replay(input, lease.id(), log);
  const ReplayStats all = replay(o);
  EXPECT_EQ(all.writers, 2u) << log.str();
  EXPECT_EQ(all.channels_over_limit, 0u);
  o.max_writers = 1;
  const ReplayStats limited = replay(o);
  EXPECT_EQ(limited.writers, 1u) << log.str();
  EXPECT_EQ(limited.channels_over_limit, 1u);
  EXPECT_EQ(limited.over_limit_messages, static_cast<uint64_t>(kImu / 10));
  EXPECT_NE(log.str().find("skipping 'attitude/live' (channel 1): more than 1 topics carry messages"), std::string::npos)
      << log.str();
}

// A fleet's recording (issue 37): every poise topic is keyed by sensor_id and the QoS profiles keep
// 256 instances per endpoint, but the replayer's reliable writers kept 8, so a recording of 20
// robots on one reliable topic lost 12 robots' messages on replay. Oracle: the file's own content
// (20 sensor_ids x 5 messages); nothing may be refused.
TEST(Replay, GivenTwentySensorIdsOnOneReliableTopicWhenReplayedThenEveryMessageIsWritten) {
  constexpr int kRobots = 20;
  constexpr int kEach = 5;
  const std::string dir = testing::cases_dir("replay-fleet");
  const std::string input = dir + "/fleet.mcap";
  {
    ClockedRecording rec(input);
    const uint16_t a = add_idl_schema(rec.writer, "poise::msg::AttitudeEstimate");
    const uint16_t ch = rec.writer.add_channel(a, "attitude/fleet", "cdr", {{"reliability", "RELIABLE"}});
    const int64_t t0 = 5'000'000'000LL;
    uint32_t seq = 0;
    for (int k = 0; k < kEach; ++k) {
      for (int r = 0; r < kRobots; ++r) {
        const int64_t stamp = t0 + (k * kRobots + r) * 1'000'000LL;
        rec.clock = stamp;
        auto e = testing::make_attitude(static_cast<uint32_t>(k), stamp);
        e.sensor_id("robot" + std::to_string(r));
        const auto bytes = testing::serialize<msg::AttitudeEstimatePubSubType>(e);
        rec.writer.write(ch, seq++, static_cast<uint64_t>(stamp), static_cast<uint64_t>(stamp),
                         bytes.data(), bytes.size());
      }
    }
    rec.writer.close();
  }
  poise::testing::DomainLease lease;
  std::ostringstream log;
  ReplayOptions o = fast_replay(input, lease.id(), log);
  const ReplayStats st = replay(o);
  EXPECT_EQ(st.write_failures, 0u) << log.str();
  EXPECT_EQ(st.schedule.delivered, static_cast<uint64_t>(kRobots * kEach)) << log.str();
}

// Outputs never open an input (issue 33, "data destroyed"): `-o` naming the input itself, or a
// symbolic link to it, is refused before anything is written; the input's bytes are the oracle.
TEST(Process, GivenTheOutputIsTheInputOrALinkToItThenItIsRefusedAndTheInputIsUnchanged) {
  const std::string dir = testing::cases_dir("process-over-input");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  const std::vector<uint8_t> before = read_bytes(input);
  const std::string link = dir + "/link.mcap";
  std::filesystem::remove(link);
  std::filesystem::create_symlink(input, link);
  for (const std::string& out : {input, link}) {
    const auto r = poise::testing::run(
        {std::string(POISE_RECORD_TOOL), "process", input, "-o", out, "--filter", "parallel_kf"}, 60s);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("is the input"), std::string::npos) << r.output;
    EXPECT_EQ(read_bytes(input), before) << "-o " << out;
  }
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(e.path().filename().string().find(".partial-"), std::string::npos) << e.path();
  }
}

// The output is replaced whole or not at all: what a failed run leaves is what was there before.
TEST(ReplacingFile, GivenNoCommitThenThePathKeepsItsBytesAndTheTemporaryIsRemoved) {
  const std::string dir = testing::cases_dir("replacing-file");
  const std::string path = dir + "/out.mcap";
  std::ofstream(path) << "old";
  std::string temporary;
  {
    ReplacingFile f(path);
    temporary = f.temporary();
    std::ofstream(temporary) << "new, unfinished";
  }
  EXPECT_EQ(read_bytes(path), (std::vector<uint8_t>{'o', 'l', 'd'}));
  EXPECT_FALSE(std::filesystem::exists(temporary));
  {
    ReplacingFile f(path);
    std::ofstream(f.temporary()) << "new";
    f.commit();
  }
  EXPECT_EQ(read_bytes(path), (std::vector<uint8_t>{'n', 'e', 'w'}));
}

// An output that is not a regular file (a device such as /dev/null, a FIFO) is written in place:
// renamed onto, it was replaced by a regular file (as root, `-o /dev/null` destroyed /dev/null).
// Oracle: the FIFO is still a FIFO and its reader received a whole MCAP file (its magic at both ends).
TEST(Process, GivenAFifoAsTheOutputThenItIsWrittenInPlaceAndStaysAFifo) {
  const std::string dir = testing::cases_dir("fifo-output");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  const std::string fifo = dir + "/out.fifo";
  std::filesystem::remove(fifo);
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::string received;
  std::thread reader([&] {
    const int fd = ::open(fifo.c_str(), O_RDONLY);  // returns once the writer opens
    char buf[65536];
    for (ssize_t n = 0; fd >= 0 && (n = ::read(fd, buf, sizeof buf)) > 0;) {
      received.append(buf, static_cast<std::size_t>(n));
    }
    if (fd >= 0) {
      ::close(fd);
    }
  });
  const auto r = poise::testing::run(
      {std::string(POISE_RECORD_TOOL), "process", input, "-o", fifo, "--filter", "parallel_kf"}, 60s);
  if (r.exit_code != 0) {
    std::ofstream(fifo).flush();  // never leave the reader waiting for a writer
  }
  reader.join();
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("no comparison: the output"), std::string::npos) << r.output;
  struct stat st {};
  ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO was replaced";
  const std::string magic = "\x89MCAP0\r\n";
  ASSERT_GT(received.size(), 2 * magic.size());
  EXPECT_EQ(received.substr(0, magic.size()), magic);
  EXPECT_EQ(received.substr(received.size() - magic.size()), magic);
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(e.path().filename().string().find(".partial-"), std::string::npos) << e.path();
  }
}

// A FIFO (or any file that is not a regular file) is refused at once by every command that reads
// a recording, never waited on: each run is bounded by kFifoRefusalBound although no writer ever
// opens the FIFO.
TEST(Process, GivenAFifoAsTheRecordingThenInfoProcessAndReplayRefuseItAtOnce) {
  constexpr auto kFifoRefusalBound = 20s;
  const std::string dir = testing::cases_dir("fifo-input");
  const std::string fifo = dir + "/input.mcap";
  std::filesystem::remove(fifo);
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string tool = POISE_RECORD_TOOL;
  const std::vector<std::vector<std::string>> commands = {
      {tool, "info", fifo},
      {tool, "info", "--verify", fifo},
      {tool, "process", fifo, "-o", dir + "/out.mcap", "--filter", "parallel_kf"},
      {tool, "replay", fifo, "--domain", "0"}};
  for (const auto& argv : commands) {
    const auto r = poise::testing::run(argv, kFifoRefusalBound);
    EXPECT_NE(r.exit_code, -1) << argv[1] << " waited on the FIFO";
    EXPECT_NE(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("is not a regular file (a FIFO)"), std::string::npos) << argv[1] << ": " << r.output;
  }
}

}  // namespace
}  // namespace poise::record

namespace poise::record {
namespace {

/// Remembers the published delays it was offered; takes them like a filter without a configured delay.
class DelaySpyFilter : public AttitudeFilter {
 public:
  explicit DelaySpyFilter(std::vector<double>* offered) : offered_(offered) {}
  bool update(const ImuSample& /*s*/) override { return true; }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override { return Eigen::Quaterniond::Identity(); }
  [[nodiscard]] bool initialized() const override { return true; }
  void reset() override {}
  bool take_published_imu_delay(double delay_s) override {
    offered_->push_back(delay_s);
    return true;
  }

 private:
  std::vector<double>* offered_;
};

/// `poise process INPUT -o OUTPUT --filter NAME` with `filter` as NAME.
ProcessStats process_alone(const std::string& input, const std::string& output, const std::string& name,
                           std::unique_ptr<AttitudeFilter> filter) {
  std::vector<ProcessFilter> filters;
  filters.push_back({name, std::move(filter), {}});
  ProcessOptions o;
  o.input = input;
  o.output = output;
  return process_recording(o, filters);
}

TEST(Process, GivenARecordingWithImuInfoWhenAFilterRunsAloneThenItIsOfferedTheRecordedDelay) {
  constexpr double kRecordedDelayS = 0.0048;  // oracle: the delay written on imu_info (MPU6050 DLPF_CFG 3)
  // GIVEN a recording: the IMU's info (sensor imu0, gyro 4.8 ms) and 20 samples of imu0
  const std::string dir = testing::cases_dir("process_imu_info");
  const std::string input = dir + "/input.mcap";
  {
    ClockedRecording rec(input);
    McapWriter& w = rec.writer;
    const uint16_t info_ch = w.add_channel(add_idl_schema(w, "poise::msg::ImuSensorInfo"), "imu_info", "cdr", {});
    const uint16_t imu = w.add_channel(add_idl_schema(w, "poise::msg::ImuSample"), "imu", "cdr", {{"qos_profile", "sensor"}});
    msg::ImuSensorInfo info;
    info.sensor_id("imu0");
    info.chip("MPU6050");
    info.filter_setting(3);
    info.accel_delay_s(0.0049);
    info.gyro_delay_s(kRecordedDelayS);
    info.origin("table");
    const auto ib = testing::serialize<msg::ImuSensorInfoPubSubType>(info);
    const int64_t t0 = 5'000'000'000LL;
    w.write(info_ch, 0, static_cast<uint64_t>(t0), static_cast<uint64_t>(t0), ib.data(), ib.size());
    for (int i = 0; i < 20; ++i) {
      const int64_t stamp = t0 + i * 10'000'000LL;
      rec.clock = stamp;
      const auto bytes = testing::serialize<msg::ImuSamplePubSubType>(testing::make_imu(static_cast<uint32_t>(i), stamp));
      w.write(imu, static_cast<uint32_t>(i), static_cast<uint64_t>(stamp + 1000), static_cast<uint64_t>(stamp),
              bytes.data(), bytes.size());
    }
    w.close();
  }
  // WHEN a filter runs alone on it (`poise process --filter`, no host file)
  std::vector<double> offered;
  const ProcessStats stats = process_alone(input, dir + "/out.mcap", "spy", std::make_unique<DelaySpyFilter>(&offered));
  // THEN it was offered the recorded gyro delay, once (before its first sample of imu0)
  EXPECT_EQ(stats.imu_infos, 1u);
  ASSERT_EQ(offered.size(), 1u);
  EXPECT_DOUBLE_EQ(offered[0], kRecordedDelayS);
}

/// Fuses the accelerometer at every sample and the magnetometer at even seq only (rejected at odd):
/// the oracle of what a processed estimate must say it fused.
class SourceSpyFilter : public AttitudeFilter {
 public:
  bool update(const ImuSample& s) override {
    seq_ = s.seq;
    return true;
  }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override { return Eigen::Quaterniond::Identity(); }
  [[nodiscard]] bool initialized() const override { return true; }
  void reset() override {}
  [[nodiscard]] SourceReports sources() const override {
    SourceReport accel(poise::Source::kAccel);
    accel.mark_fused(0);
    SourceReport mag(poise::Source::kMag);
    if (seq_ % 2 == 0) {
      mag.mark_fused(0);
    } else {
      mag.mark_rejected("disturbed");
    }
    return {accel, mag};
  }

 private:
  uint32_t seq_ = 0;
};

TEST(Process, GivenAFilterRunAloneWhenItReportsItsSourcesThenEachEstimateSaysWhatItFusedAsTheLiveNodeDoes) {
  // GIVEN a recording of 500 IMU samples and a filter whose magnetometer is fused at even seq only
  const std::string dir = testing::cases_dir("process_sources");
  const std::string input = dir + "/input.mcap";
  write_input(input);
  // WHEN it runs alone (`poise process --filter`)
  const ProcessStats stats = process_alone(input, dir + "/out.mcap", "spy", std::make_unique<SourceSpyFilter>());
  // THEN every processed estimate carries mag_trusted and sources_fused as its sample's report says
  const McapReader out = McapReader::open_file(dir + "/out.mcap");
  MessageCursor cursor = out.messages();
  uint64_t estimates = 0;
  uint64_t trusted = 0;
  while (const MessageView* m = cursor.next()) {
    if (m->channel->topic != "processed/attitude/spy") {
      continue;
    }
    msg::AttitudeEstimate e;
    ASSERT_TRUE(decode_attitude(*m, e));
    ++estimates;
    const bool even = e.header().seq() % 2 == 0;
    EXPECT_EQ(e.mag_trusted(), even) << "seq " << e.header().seq();
    EXPECT_EQ((e.sources_fused() & msg::SOURCE_MAG) != 0, even) << "seq " << e.header().seq();
    EXPECT_NE(e.sources_fused() & msg::SOURCE_ACCEL, 0u) << "seq " << e.header().seq();
    trusted += e.mag_trusted() ? 1 : 0;
  }
  EXPECT_EQ(estimates, stats.estimates.at("spy"));
  EXPECT_EQ(trusted, static_cast<uint64_t>(kImu / 2));  // seq 0..499: 250 even
}

}  // namespace
}  // namespace poise::record
