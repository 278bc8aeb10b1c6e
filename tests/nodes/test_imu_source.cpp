// One IMU per component: a filter fed two interleaved sensors (two drivers on one topic, or anyone
// else publishing on it) would fuse both. StepRunner follows one sensor_id (configured by
// `imu_sensor_id`, else the first heard); samples of any other are never stepped, counted
// (`imu_other_sensor`) and said once, printable whatever the name's bytes. Driven with a fake step
// that records what it was given (the oracle: exactly the followed sensor's seqs), no DDS.
#include "poise/nodes/estimator_step.h"
#include "poise/testing/testing.h"
#include "node_spec.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace poise::nodes {
namespace {

constexpr int64_t kSampleStepNs = 5'000'000;  // 200 Hz per sensor
constexpr uint32_t kSeqOfB = 1000;             // sensor b numbers its samples from here
constexpr int kSamplesEach = 100;

/// Accepts every sample and keeps the seq of each it was given.
class RecordingStep : public EstimatorStep {
 public:
  explicit RecordingStep(std::vector<uint32_t>* stepped) : EstimatorStep("pkf", "parallel_kf"), stepped_(stepped) {}
  [[nodiscard]] unsigned kinds() const override { return kAttitudeOut; }
  bool step(const ImuSample& sample) override {
    stepped_->push_back(sample.seq);
    return true;
  }
  bool estimate(const ImuSample& /*sample*/, StepOutputs& /*out*/) override { return false; }
  void diagnostics(DiagnosticsReport& /*diag*/) const override {}

 private:
  std::vector<uint32_t>* stepped_;
};

class Collected : public StepOutputs {
 public:
  void attitude(const msg::AttitudeEstimate& /*m*/) override {}
  void pose(const msg::PoseEstimate& /*m*/) override {}
  void altitude(const msg::AltitudeEstimate& /*m*/) override {}
  void diagnostics(const msg::FilterDiagnostics& m) override { last = m; }
  msg::FilterDiagnostics last;
};

int64_t counter_or_minus_one(const msg::FilterDiagnostics& m, const std::string& name) {
  for (const auto& c : m.counters()) {
    if (c.name().to_string() == name) {
      return static_cast<int64_t>(c.value());
    }
  }
  return -1;
}

/// Sensors `first` and `second` interleaved sample by sample (first's seq from 0, second's from
/// kSeqOfB), `kSamplesEach` each; the log messages the runner gave along the way.
struct Interleaved {
  std::vector<uint32_t> stepped;
  std::vector<std::string> said;
  Collected out;
  int64_t now_ns = 0;
  StepRunner runner;
  explicit Interleaved(const NodeParams& p)
      : runner(std::make_unique<RecordingStep>(&stepped), p, dds::TopicNames{}, [this] { return now_ns; }) {}
  void feed(const std::string& first, const std::string& second) {
    for (int i = 0; i < kSamplesEach; ++i) {
      for (const auto& [source, seq0] : {std::pair{first, 0U}, std::pair{second, kSeqOfB}}) {
        ImuSample s;
        s.seq = seq0 + static_cast<uint32_t>(i);
        s.stamp_ns = now_ns;
        runner.imu(s, source, "writer_" + source, out);
        if (std::string m = runner.take_log_message(); !m.empty()) {
          said.push_back(m);
        }
      }
      now_ns += kSampleStepNs;
    }
  }
};

std::vector<uint32_t> seqs_from(uint32_t first) {
  std::vector<uint32_t> v;
  for (int i = 0; i < kSamplesEach; ++i) {
    v.push_back(first + static_cast<uint32_t>(i));
  }
  return v;
}

TEST(ImuSource, GivenTwoImusInterleavedOnTheTopicWhenNoneIsConfiguredThenOnlyTheFirstHeardIsStepped) {
  Interleaved f(node_params(spec_with("{diagnostics_every: 1}")));
  f.feed("a", "b");
  EXPECT_EQ(f.stepped, seqs_from(0)) << "exactly a's samples, in order";
  EXPECT_EQ(f.runner.followed_imu(), "a");
  EXPECT_EQ(f.runner.imu_other_sensor(), static_cast<uint64_t>(kSamplesEach));
  f.now_ns += 2'000'000'000;  // silent for 2 s: the timer's diagnostics hold every count so far
  ASSERT_TRUE(f.runner.periodic_diagnostics(f.out));
  EXPECT_EQ(counter_or_minus_one(f.out.last, "imu_other_sensor"), kSamplesEach);
  EXPECT_EQ(counter_or_minus_one(f.out.last, "samples_received"), kSamplesEach);
  ASSERT_EQ(f.said.size(), 1U) << "said once, not per sample";
  EXPECT_NE(f.said[0].find("ignoring the samples of IMU 'b'"), std::string::npos) << f.said[0];
  EXPECT_NE(f.said[0].find("follows 'a' (the first one heard; imu_sensor_id chooses)"), std::string::npos) << f.said[0];
  EXPECT_NE(f.runner.other_imu_summary().find("followed IMU 'a', 100 sample(s) of other IMUs"), std::string::npos)
      << f.runner.other_imu_summary();
}

TEST(ImuSource, GivenImuSensorIdConfiguredWhenAnotherIsHeardFirstThenOnlyTheConfiguredOneIsStepped) {
  Interleaved f(node_params(spec_with("{imu_sensor_id: b, diagnostics_every: 1}")));
  f.feed("a", "b");
  EXPECT_EQ(f.stepped, seqs_from(kSeqOfB));
  EXPECT_EQ(f.runner.imu_other_sensor(), static_cast<uint64_t>(kSamplesEach));
  ASSERT_EQ(f.said.size(), 1U);
  EXPECT_NE(f.said[0].find("follows 'b' (imu_sensor_id)"), std::string::npos) << f.said[0];
}

TEST(ImuSource, GivenOneImuThenEverySampleIsSteppedAndNoOtherSensorCounterIsPublished) {
  Interleaved f(node_params(spec_with("{diagnostics_every: 1}")));
  f.feed("a", "a");  // one sensor (two seq ranges: a restart's numbering, still sensor a)
  EXPECT_EQ(f.stepped.size(), static_cast<std::size_t>(2 * kSamplesEach));
  EXPECT_EQ(f.runner.imu_other_sensor(), 0U);
  EXPECT_EQ(counter_or_minus_one(f.out.last, "imu_other_sensor"), -1) << "no counter when nothing was ignored";
  EXPECT_TRUE(f.said.empty());
  EXPECT_TRUE(f.runner.other_imu_summary().empty());
}

TEST(ImuSource, GivenAHostileSensorIdThenTheMessageIsPrintableAndItsSamplesAreNotStepped) {
  Interleaved f(node_params(spec_with("{}")));
  const std::string hostile = std::string("x\n\x1b[2J") + '\0' + "\xff";
  f.feed("a", hostile);
  EXPECT_EQ(f.stepped, seqs_from(0));
  ASSERT_EQ(f.said.size(), 1U);
  for (const char c : f.said[0]) {
    EXPECT_TRUE(c >= ' ' && c <= '~') << "byte " << static_cast<int>(static_cast<unsigned char>(c));
  }
  EXPECT_NE(f.said[0].find("'x\\x0A\\x1B[2J\\x00\\xFF'"), std::string::npos) << f.said[0];
}

TEST(ImuSource, GivenAnImuSensorIdLongerThanTheIdlBoundWhenReadThenTheErrorNamesTheKey) {
  try {
    (void)node_params(spec_with("{imu_sensor_id: " + std::string(65, 'x') + "}"));
    ADD_FAILURE() << "a 65-character imu_sensor_id was accepted";
  } catch (const runtime::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("imu_sensor_id"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace poise::nodes
