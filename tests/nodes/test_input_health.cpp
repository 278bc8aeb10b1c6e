// Loss and silence of a node's inputs (issue 22): InputHealth on its own (explicit times and seqs as
// the oracle), and a running parallel_kf node that publishes diagnostics on a timer while its input
// is dead and counts the exact number of samples the test left out of the sequence.
#include "node_harness.h"

#include "poise/nodes/input_health.h"

#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include <vector>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;
constexpr int64_t kSecond = 1'000'000'000;

double metric(const nodes::DiagnosticsReport& r, const std::string& name) {
  for (const auto& m : r.metrics) {
    if (m.name == name) {
      return m.value;
    }
  }
  ADD_FAILURE() << "no metric " << name;
  return -1.0;
}

TEST(InputHealth, CountsGapsRestartsAndSilenceAgainstTheDeadline) {
  nodes::InputHealth h(kSecond / 2, 10 * kSecond);  // deadline 0.5 s, listening since t = 10 s
  h.expect("imu");
  nodes::DiagnosticsReport r;
  h.report(10 * kSecond + kSecond / 4, r);
  EXPECT_EQ(r.counters["imu_silences"], 0U) << "0.25 s without input is within the deadline";
  EXPECT_DOUBLE_EQ(metric(r, "imu_silent"), 0.0);
  r = {};
  h.report(12 * kSecond, r);  // 2 s since start, nothing yet
  EXPECT_EQ(r.counters["imu_silences"], 1U);
  EXPECT_DOUBLE_EQ(metric(r, "imu_silence"), 2.0);
  EXPECT_DOUBLE_EQ(metric(r, "imu_silent"), 1.0);
  EXPECT_EQ(nodes::describe_silence(h.silent(12 * kSecond)), "no input on imu for 2.0 s");

  // seq 0..9, then 20..29 (10 lost), then a new writer starting at 0 (a restart, not a loss).
  int64_t t = 12 * kSecond;
  for (uint32_t s = 0; s < 10; ++s) h.on_sample("imu", "imu0", s, "w1", t += kSecond / 100);
  EXPECT_EQ(h.on_sample("imu", "imu0", 20, "w1", t += kSecond / 100), 10U);
  for (uint32_t s = 21; s < 30; ++s) h.on_sample("imu", "imu0", s, "w1", t += kSecond / 100);
  EXPECT_EQ(h.on_sample("imu", "imu0", 0, "w2", t += kSecond / 100), 0U);
  r = {};
  h.report(t, r);
  EXPECT_EQ(r.counters["imu_received"], 21U);
  EXPECT_EQ(r.counters["imu_lost"], 10U);
  EXPECT_EQ(r.counters["imu_gaps"], 1U);
  EXPECT_EQ(r.counters["imu_restarts"], 1U);
  EXPECT_DOUBLE_EQ(metric(r, "imu_silent"), 0.0);
  EXPECT_TRUE(h.silent(t).empty());

  // A second silence is a second episode, counted once however many reports see it.
  r = {};
  h.report(t + 3 * kSecond, r);
  r = {};
  h.report(t + 4 * kSecond, r);
  EXPECT_EQ(r.counters["imu_silences"], 2U);
  EXPECT_DOUBLE_EQ(metric(r, "imu_silence"), 4.0);
}

TEST(InputHealth, OptionalInputsAreReportedFromTheirFirstSample) {
  nodes::InputHealth h(kSecond / 2, 0);
  h.expect("imu");
  nodes::DiagnosticsReport r;
  h.report(5 * kSecond, r);
  EXPECT_EQ(r.counters.count("vision_pose_received"), 0U);
  h.on_sample("vision_pose", "cam0", 7, "w", 5 * kSecond);
  r = {};
  h.report(7 * kSecond, r);
  EXPECT_EQ(r.counters["vision_pose_received"], 1U);
  EXPECT_EQ(nodes::describe_silence(h.silent(7 * kSecond)),
            "no input on imu for 7.0 s; no input on vision_pose for 2.0 s");
}

/// Every diagnostics message of the node, in arrival order.
class DiagnosticsLog {
 public:
  explicit DiagnosticsLog(dds::Participant& p)
      : reader_(p, "diagnostics", [this](const msg::FilterDiagnostics& m, const auto&) {
          std::lock_guard<std::mutex> lock(mutex_);
          all_.push_back(m);
        }) {}
  /// The first message (waiting up to 15 s) for which `pred` holds.
  template <class Pred>
  std::optional<msg::FilterDiagnostics> wait_for(Pred pred) {
    std::optional<msg::FilterDiagnostics> out;
    wait_until([&] {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const auto& m : all_) {
        if (pred(m)) {
          out = m;
          return true;
        }
      }
      return false;
    }, 15s);
    return out;
  }

 private:
  std::mutex mutex_;
  std::vector<msg::FilterDiagnostics> all_;
  dds::Reader<msg::FilterDiagnosticsPubSubType> reader_;
};

double published_metric(const msg::FilterDiagnostics& d, const std::string& name) {
  for (const auto& m : d.metrics()) {
    if (m.name() == name) {
      return m.value();
    }
  }
  return -1.0;
}

// GIVEN a parallel_kf node (input deadline 0.5 s, diagnostics every 0.2 s by timer)
// WHEN no IMU sample comes THEN its diagnostics still arrive and say the imu input is silent;
// WHEN seq 0..99 and 130..199 are published (reliable: nothing else is lost) THEN it reports
// exactly 30 lost, 170 received; WHEN the input stops again THEN the silence is reported again.
TEST(ImuEstimatorNode, DiagnosticsOnATimerReportSilenceAndTheExactLoss) {
  NodeHarness h("{type: parallel_kf, name: pkf, params: {diagnostics_period_s: 0.2, "
                "input_deadline_s: 0.5}}");
  DiagnosticsLog log(h.participant());
  ASSERT_TRUE(h.connected());
  const auto silent = log.wait_for([](const msg::FilterDiagnostics& d) {
    return published_metric(d, "imu_silent") == 1.0 && published_metric(d, "imu_silence") >= 0.5;
  });
  ASSERT_TRUE(silent) << "no timer diagnostics reporting the dead input";
  EXPECT_EQ(published_counter(*silent, "imu_received"), 0U);

  for (uint32_t seq = 0; seq < 200; ++seq) {
    if (seq < 100 || seq >= 130) {
      h.publish(rest_sample(seq));
    }
  }
  const auto counted = log.wait_for([](const msg::FilterDiagnostics& d) {  // seq 199 arrived
    return published_counter(d, "imu_received") + published_counter(d, "imu_lost") == 200U;
  });
  ASSERT_TRUE(counted) << "the node did not see the last sample published";
  EXPECT_EQ(published_counter(*counted, "imu_received"), 170U);
  EXPECT_EQ(published_counter(*counted, "imu_lost"), 30U);
  EXPECT_EQ(published_counter(*counted, "imu_gaps"), 1U);
  EXPECT_EQ(published_counter(*counted, "imu_restarts"), 0U);
  const uint64_t silences_before = published_counter(*counted, "imu_silences");

  const auto silent_again = log.wait_for([&](const msg::FilterDiagnostics& d) {
    return published_counter(d, "imu_received") + published_counter(d, "imu_lost") == 200U &&
           published_metric(d, "imu_silent") == 1.0;
  });
  ASSERT_TRUE(silent_again) << "the silence after the input stopped was not reported";
  EXPECT_EQ(published_counter(*silent_again, "imu_silences"), silences_before + 1);
  EXPECT_EQ(published_counter(*silent_again, "imu_lost"), published_counter(*counted, "imu_lost"));
}

}  // namespace
}  // namespace poise::testing
