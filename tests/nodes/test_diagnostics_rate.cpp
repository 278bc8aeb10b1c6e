// Diagnostics at a configurable rate (issue 34): by default a few per second whatever the input
// rate, with counters cumulative so nothing is lost between two; per sample only when asked
// (diagnostics_every); the live timer adds diagnostics only while the input is silent. StepRunner
// is driven with an injected clock and a fake step, no DDS.
#include "poise/nodes/estimator_step.h"
#include "poise/testing/testing.h"
#include "node_spec.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace poise::nodes {
namespace {

constexpr int64_t kSampleStepNs = 5'000'000;  // 200 Hz input
constexpr int64_t kSecondNs = 1'000'000'000;

/// Accepts every sample, writes nothing, and reports how many steps it took (a cumulative counter).
class CountingStep : public EstimatorStep {
 public:
  CountingStep() : EstimatorStep("pkf", "parallel_kf") {}
  [[nodiscard]] unsigned kinds() const override { return kAttitudeOut; }
  bool step(const ImuSample& /*sample*/) override {
    ++steps_;
    return true;
  }
  bool estimate(const ImuSample& /*sample*/, StepOutputs& /*out*/) override { return false; }
  void diagnostics(DiagnosticsReport& diag) const override { diag.counters["core_steps"] = steps_; }

 private:
  uint64_t steps_ = 0;
};

class Collected : public StepOutputs {
 public:
  void attitude(const msg::AttitudeEstimate& /*m*/) override {}
  void pose(const msg::PoseEstimate& /*m*/) override {}
  void altitude(const msg::AltitudeEstimate& /*m*/) override {}
  void diagnostics(const msg::FilterDiagnostics& m) override { all.push_back(m); }
  std::vector<msg::FilterDiagnostics> all;
};

uint64_t counter(const msg::FilterDiagnostics& m, const std::string& name) {
  for (const auto& c : m.counters()) {
    if (c.name().to_string() == name) {
      return c.value();
    }
  }
  ADD_FAILURE() << "no counter " << name;
  return 0;
}

/// A runner on a clock the test moves, fed `n` samples at 200 Hz from t = 0.
struct Fed {
  int64_t now_ns = 0;
  Collected out;
  std::unique_ptr<StepRunner> runner;
  explicit Fed(const NodeParams& p) {
    runner = std::make_unique<StepRunner>(std::make_unique<CountingStep>(), p, dds::TopicNames{},
                                          [this] { return now_ns; });
  }
  void feed(int n) {
    for (int i = 0; i < n; ++i) {
      ImuSample s;
      s.seq = seq_++;
      s.stamp_ns = now_ns;
      runner->imu(s, "imu0", "writer", out);
      now_ns += kSampleStepNs;
    }
  }

 private:
  uint32_t seq_ = 0;
};

TEST(DiagnosticsRate, GivenTheDefaultRateWhenSamplesComeAt200HzThenFiveDiagnosticsASecondWithCumulativeCounters) {
  Fed f(node_params(spec_with("{}")));
  EXPECT_EQ(f.runner->params().diagnostics_rate_hz, 5.0);
  f.feed(1000);  // 5 s
  // one at t = 0, then one every 0.2 s of the clock: t = 0, 0.2, ..., 4.8 s
  ASSERT_EQ(f.out.all.size(), 25U);
  for (std::size_t i = 0; i < f.out.all.size(); ++i) {
    const auto& m = f.out.all[i];
    const uint64_t samples_so_far = 40 * i + 1;  // 40 samples per 0.2 s, the one published included
    EXPECT_EQ(m.header().seq(), 40 * i) << i;
    EXPECT_EQ(counter(m, "samples_received"), samples_so_far) << "cumulative: none lost between two";
    EXPECT_EQ(counter(m, "core_steps"), samples_so_far) << "the core's counters too";
  }
}

TEST(DiagnosticsRate, GivenARateOrEveryNWhenSetThenThatManyComeAndPerSampleOnlyWhenAsked) {
  Fed fast(node_params(spec_with("{diagnostics_rate_hz: 20}")));
  fast.feed(200);  // 1 s
  EXPECT_EQ(fast.out.all.size(), 20U);
  Fed every(node_params(spec_with("{diagnostics_every: 1}")));
  every.feed(200);
  EXPECT_EQ(every.out.all.size(), 200U) << "every sample when asked";
  Fed tenth(node_params(spec_with("{diagnostics_every: 10}")));
  tenth.feed(200);
  ASSERT_EQ(tenth.out.all.size(), 20U);
  EXPECT_EQ(tenth.out.all.front().header().seq(), 9U);
}

TEST(DiagnosticsRate, GivenASilentInputWhenTheTimerFiresThenItPublishesAndWhileInputFlowsItAddsNothing) {
  Fed f(node_params(spec_with("{diagnostics_period_s: 1.0}")));
  f.feed(200);  // input flows for 1 s: the input path publishes every 0.2 s
  const std::size_t flowing = f.out.all.size();
  EXPECT_FALSE(f.runner->periodic_diagnostics(f.out)) << "published 0.2 s ago: nothing to add";
  EXPECT_EQ(f.out.all.size(), flowing);
  f.now_ns += kSecondNs;  // the input falls silent
  EXPECT_TRUE(f.runner->periodic_diagnostics(f.out));
  f.now_ns += kSecondNs;
  EXPECT_TRUE(f.runner->periodic_diagnostics(f.out)) << "every period while silent";
  EXPECT_EQ(f.out.all.size(), flowing + 2);
  EXPECT_EQ(counter(f.out.all.back(), "samples_received"), 200U);
}

TEST(DiagnosticsRate, GivenABadRateOrCountWhenReadThenTheErrorNamesTheKeyAndItsRange) {
  const auto error = [](const std::string& params) {
    try {
      (void)node_params(spec_with(params));
    } catch (const runtime::ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error("{diagnostics_rate_hz: 0}").find("diagnostics_rate_hz must be in [0.01, 1000] Hz"), std::string::npos);
  EXPECT_NE(error("{diagnostics_rate_hz: .nan}").find("diagnostics_rate_hz"), std::string::npos);
  EXPECT_NE(error("{diagnostics_every: -1}").find("diagnostics_every must be >= 0"), std::string::npos);
}

double metric(const msg::FilterDiagnostics& m, const std::string& name) {
  for (const auto& k : m.metrics()) {
    if (k.name().to_string() == name) {
      return k.value();
    }
  }
  ADD_FAILURE() << "no metric " << name;
  return -1.0;
}

// Issue 37: no estimator fuses stale input. A stream on the publisher's clock (0.25 s ahead of
// the runner's), then the stale burst a link cut leaves (20 samples sent 0.8 .. 0.705 s before they
// arrive), 10 samples 0.3 s late, then the fresh flow. Oracle: the test's own arrival and send
// times.
TEST(StepRunnerAge, GivenAStaleBurstWhenFedThenItIsCountedStaleNeverSteppedAndTheFusedAgesAreReported) {
  constexpr int64_t kPublisherAhead = 250'000'000;
  constexpr int kFresh = 200;
  constexpr int kStale = 20;
  constexpr int kLate = 10;
  constexpr double kLateAgeS = 0.3;
  constexpr double kDriftToleranceS = 1e-3;  // InputAge::kDriftAllowance over ~1.2 s, and more
  for (const std::string method : {"relative", "host_clock", "off"}) {
    SCOPED_TRACE(method);
    Fed f(node_params(spec_with("{diagnostics_every: 1, input_age: " + method + "}")));
    const int64_t ahead = method == "host_clock" ? 0 : kPublisherAhead;  // host_clock: same clock
    uint32_t seq = 0;
    const auto send = [&](int64_t sent_ns) {
      ImuSample s;
      s.seq = seq++;
      s.stamp_ns = sent_ns + ahead;
      f.runner->imu(s, "imu0", "writer", f.out);
    };
    for (int i = 0; i < kFresh; ++i, f.now_ns += kSampleStepNs) {
      send(f.now_ns);
    }
    for (int i = 0; i < kStale; ++i) {  // arrive together
      send(f.now_ns - 800'000'000 + i * kSampleStepNs);
    }
    for (int i = 0; i < kLate; ++i, f.now_ns += kSampleStepNs) {
      send(f.now_ns - static_cast<int64_t>(kLateAgeS * 1e9));
    }
    for (int i = 0; i < kFresh; ++i, f.now_ns += kSampleStepNs) {
      send(f.now_ns);
    }
    const msg::FilterDiagnostics& last = f.out.all.back();
    const uint64_t total = 2 * kFresh + kStale + kLate;
    EXPECT_EQ(counter(last, "samples_received"), total);
    if (method == "off") {
      EXPECT_EQ(counter(last, "core_steps"), total) << "nothing judged";
      EXPECT_EQ(f.runner->stale(), 0U);
      continue;
    }
    EXPECT_EQ(counter(last, "imu_stale"), static_cast<uint64_t>(kStale));
    EXPECT_EQ(f.runner->stale(), static_cast<uint64_t>(kStale));
    EXPECT_EQ(counter(last, "core_steps"), total - kStale) << "a stale sample is never stepped";
    EXPECT_EQ(counter(last, "samples_rejected"), 0U) << "stale is its own reason, not the core's";
    EXPECT_NEAR(metric(last, "imu_age_max"), kLateAgeS, kDriftToleranceS);
    EXPECT_NEAR(metric(last, "imu_age"), 0.0, kDriftToleranceS);
    EXPECT_NE(f.runner->status().find("stale 20"), std::string::npos) << f.runner->status();
  }
}

TEST(StepRunnerAge, GivenTheDefaultOrABadInputAgeWhenReadThenRelativeOrAnErrorNamingTheKeyAndTheMethods) {
  EXPECT_EQ(node_params(spec_with("{}")).input_age, AgeMethod::kRelative);
  try {
    (void)node_params(spec_with("{input_age: wall}"));
    FAIL() << "accepted";
  } catch (const runtime::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("input_age: 'wall' is not an input age method (relative, host_clock, off)"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace poise::nodes
