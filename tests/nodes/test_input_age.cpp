// The age of input samples and the stale rule (issue 37), InputAge on its own. The oracle is a
// simulated stream whose true send and arrival times the test knows: the publisher's clock differs
// from the host's by a constant (ahead or behind, as two unsynchronised CLOCK_MONOTONICs do), a
// link cut holds samples back and delivers the last ones at once when it returns (the kernel's
// neighbour queue), then the flow is fresh again.
#include "poise/nodes/input_age.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <stdexcept>
#include <vector>

namespace poise::nodes {
namespace {

constexpr int64_t kMs = 1'000'000;
constexpr int64_t kSecond = 1000 * kMs;
constexpr int64_t kDeadline = 500 * kMs;   // the input deadline (default input_deadline_s)
constexpr int64_t kPeriod = 10 * kMs;      // 100 Hz
constexpr int64_t kDelay = 1 * kMs;        // delivery delay outside the cut
constexpr int64_t kCutStart = 10 * kSecond;
constexpr int64_t kCutEnd = 15 * kSecond;  // link up
constexpr int64_t kHeldBack = 800 * kMs;   // the samples of the cut's last 0.8 s arrive at once
constexpr int64_t kBurstArrival = kCutEnd + 500'000;  // 15.0005 s, before the first fresh one
// The reference may rise by kDriftAllowance s/s: over the cut the judged age is short by at most
// this much (5.1 s x 500 ppm); the burst's true ages are >= 4.5 ms away from the deadline (samples
// are sent at x.xx5 s).
constexpr int64_t kAllowanceToleranceNs = 2'550'000;

struct Sample {
  int64_t sent;     // host time of creation (the truth)
  int64_t arrival;  // host time of arrival
};

/// 100 Hz from t = 1.005 s to 20 s; samples created during the cut are lost except the last
/// kHeldBack, which arrive together at kBurstArrival.
std::vector<Sample> stream_with_cut() {
  std::vector<Sample> out;
  for (int64_t t = kSecond + 5 * kMs; t < 20 * kSecond; t += kPeriod) {
    if (t < kCutStart || t >= kCutEnd) {
      out.push_back({t, t + kDelay});
    } else if (t >= kCutEnd - kHeldBack) {
      out.push_back({t, kBurstArrival});
    }
  }
  std::stable_sort(out.begin(), out.end(), [](const Sample& a, const Sample& b) { return a.arrival < b.arrival; });
  return out;
}

// GIVEN a publisher whose clock is 0.99 s behind or 500000 s ahead of this host's (stamps on its
// clock), a 5 s cut whose last 0.8 s of samples arrive at once when the link returns
// WHEN every sample is judged with the relative method, deadline 0.5 s
// THEN exactly those whose true extra delay exceeds 0.5 s are stale, every judged age equals the
// true extra delay (within the drift allowance), and the fresh flow afterwards is age 0.
TEST(InputAge, GivenUnsynchronisedClocksAndAStaleBurstWhenJudgedRelativelyThenExactlyTheSamplesOlderThanTheDeadlineAreStale) {
  for (const int64_t clock_offset : {int64_t{-987'654'321}, 500'000 * kSecond}) {
    SCOPED_TRACE(clock_offset);
    InputAge age(AgeMethod::kRelative, kDeadline);
    uint64_t expected_stale = 0;
    int64_t oldest_fused = 0;
    for (const Sample& s : stream_with_cut()) {
      const int64_t true_extra = s.arrival - s.sent - kDelay;  // oracle: beyond the normal delay
      const bool truly_stale = true_extra > kDeadline;
      expected_stale += truly_stale ? 1U : 0U;
      const InputAge::Verdict v = age.judge("imu", "w1", s.sent + clock_offset, s.arrival);
      EXPECT_EQ(v.stale, truly_stale) << "sent " << s.sent << " arrived " << s.arrival;
      EXPECT_NEAR(static_cast<double>(v.age_ns), static_cast<double>(true_extra),
                  static_cast<double>(kAllowanceToleranceNs));
      if (!v.stale) {
        age.fused("imu", v.age_ns);
        oldest_fused = std::max(oldest_fused, v.age_ns);
      }
    }
    constexpr uint64_t kBurstOverDeadline = 30;  // sent 14.205 .. 14.495 s: 0.5045 .. 0.7945 s late
    EXPECT_EQ(expected_stale, kBurstOverDeadline);
    EXPECT_EQ(age.stale("imu"), expected_stale);
    DiagnosticsReport r;
    age.report(r);
    EXPECT_EQ(r.counters.at("imu_stale"), expected_stale);
    ASSERT_EQ(r.metrics.size(), 2U);
    EXPECT_EQ(r.metrics[0].name, "imu_age");
    EXPECT_DOUBLE_EQ(r.metrics[0].value, 0.0);  // the last sample fused came fresh
    EXPECT_EQ(r.metrics[1].name, "imu_age_max");
    EXPECT_DOUBLE_EQ(r.metrics[1].value, static_cast<double>(oldest_fused) * 1e-9);
    EXPECT_LE(r.metrics[1].value, 0.5);  // every fused sample within the deadline
    EXPECT_GT(r.metrics[1].value, 0.49);  // the burst's 0.4945 s one was fused
  }
}

// GIVEN a steady stream whose publisher clock runs 100 ppm slow or fast (drift within allowance)
// WHEN judged for 100 s THEN no sample is stale and no age exceeds 0.1 ms.
TEST(InputAge, GivenClocksDriftingApartWithinTheAllowanceWhenJudgedThenNothingIsStale) {
  constexpr double kPpm = 1e-6;
  constexpr double kMaxFreshAgeNs = 0.1e6;
  for (const double drift : {-100 * kPpm, 100 * kPpm}) {
    InputAge age(AgeMethod::kRelative, kDeadline);
    for (int64_t t = kSecond; t < 101 * kSecond; t += 5 * kMs) {
      const auto stamp = static_cast<int64_t>(static_cast<double>(t) * (1.0 + drift));
      const InputAge::Verdict v = age.judge("imu", "w", stamp, t + kDelay);
      EXPECT_FALSE(v.stale);
      EXPECT_LE(static_cast<double>(v.age_ns), kMaxFreshAgeNs);
    }
    EXPECT_EQ(age.stale("imu"), 0U);
  }
}

// GIVEN a 100 Hz publisher whose clock jumps back by 100 s at t = 5 s (reset; a replay looping)
// WHEN judged THEN its samples are stale for kReanchorAfterNs (1 s) of arrivals, then a new
// reference starts (counted) and the flow is fresh again.
TEST(InputAge, GivenAPublisherClockResetWhenJudgedThenStaleForOneSecondThenANewReference) {
  InputAge age(AgeMethod::kRelative, kDeadline);
  constexpr int64_t kJump = 5 * kSecond;
  uint64_t stale_after_reanchor = 0;
  for (int64_t t = kSecond; t < 10 * kSecond; t += kPeriod) {
    const int64_t stamp = t + (t < kJump ? 200 * kSecond : 100 * kSecond);
    const bool stale = age.judge("imu", "w", stamp, t + kDelay).stale;
    stale_after_reanchor += (stale && t > kJump + InputAge::kReanchorAfterNs) ? 1U : 0U;
  }
  // oracle: the samples arriving 5.00 .. 6.00 s after the jump (the run's first + 1 s)
  constexpr uint64_t kStaleRun = InputAge::kReanchorAfterNs / kPeriod + 1;
  EXPECT_EQ(age.stale("imu"), kStaleRun);
  EXPECT_EQ(stale_after_reanchor, 0U);
  DiagnosticsReport r;
  age.report(r);
  EXPECT_EQ(r.counters.at("imu_age_reanchored"), 1U);
}

// GIVEN one sample stamped a day ahead in a steady 100 Hz stream, then a clock that really jumps
// ahead by 100 s WHEN judged THEN the lone glitch is not adopted (nothing after it is stale) and the
// jump is adopted at its second sample (nothing after it is stale either). Oracle: the stream.
TEST(InputAge, GivenOneStampFarAheadThenAClockJumpAheadWhenJudgedThenNeitherMakesLaterSamplesStale) {
  InputAge age(AgeMethod::kRelative, kDeadline);
  constexpr int64_t kDay = 86400 * kSecond;
  constexpr int64_t kJumpAt = 6 * kSecond;
  for (int64_t t = kSecond; t < 10 * kSecond; t += kPeriod) {
    int64_t stamp = t < kJumpAt ? t : t + 100 * kSecond;
    if (t == 3 * kSecond) {
      stamp += kDay;
    }
    EXPECT_FALSE(age.judge("imu", "w", stamp, t + kDelay).stale) << "t = " << t / kMs << " ms";
  }
  EXPECT_EQ(age.stale("imu"), 0U);
}

// GIVEN two publishers, b's clock 3 s behind a's, and a sample repaired 0.8 s late (a reliable
// resend arriving after newer ones) WHEN judged THEN each has its own reference, and the late one
// is stale without disturbing the flow after it.
TEST(InputAge, GivenTwoPublishersAndALateRepairWhenJudgedThenEachHasItsOwnReferenceAndTheLateOneIsStale) {
  InputAge age(AgeMethod::kRelative, kDeadline);
  for (int i = 0; i < 100; ++i) {
    const int64_t t = 10 * kSecond + i * kPeriod;
    EXPECT_FALSE(age.judge("vision_pose", "a", 100 * kSecond + i * kPeriod, t).stale);
    EXPECT_FALSE(age.judge("vision_pose", "b", 97 * kSecond + i * kPeriod, t).stale);
  }
  const int64_t now = 10 * kSecond + 100 * kPeriod;  // 11 s
  const InputAge::Verdict repaired = age.judge("vision_pose", "a", 100 * kSecond + 20 * kPeriod, now);
  EXPECT_TRUE(repaired.stale);
  EXPECT_NEAR(static_cast<double>(repaired.age_ns), 800.0 * kMs, static_cast<double>(kAllowanceToleranceNs));
  EXPECT_FALSE(age.judge("vision_pose", "a", 100 * kSecond + 100 * kPeriod, now).stale);
  EXPECT_FALSE(age.judge("vision_pose", "b", 97 * kSecond + 100 * kPeriod, now).stale);
  EXPECT_EQ(age.stale("vision_pose"), 1U);
}

// GIVEN the host-clock method (publisher on this host) WHEN a sample arrives 0.7 s after its stamp,
// 0.2 s after, or stamped in the future THEN its age is arrival - stamp (0 for the future), and
// only the first is stale.
TEST(InputAge, GivenTheHostClockMethodWhenJudgedThenTheAgeIsArrivalMinusStamp) {
  InputAge age(AgeMethod::kHostClock, kDeadline);
  const InputAge::Verdict late = age.judge("imu", "w", 10 * kSecond, 10 * kSecond + 700 * kMs);
  EXPECT_TRUE(late.stale);
  EXPECT_EQ(late.age_ns, 700 * kMs);
  const InputAge::Verdict ok = age.judge("imu", "w", 10 * kSecond, 10 * kSecond + 200 * kMs);
  EXPECT_FALSE(ok.stale);
  EXPECT_EQ(ok.age_ns, 200 * kMs);
  const InputAge::Verdict future = age.judge("imu", "w", 11 * kSecond, 10 * kSecond);
  EXPECT_FALSE(future.stale);
  EXPECT_EQ(future.age_ns, 0);
  EXPECT_EQ(age.stale("imu"), 1U);
}

// GIVEN stamps outside [0, 2^62] ns (hostile or broken) WHEN judged THEN no overflow and not
// stale here (the cores refuse such stamps with their own reason); with kOff nothing is judged.
TEST(InputAge, GivenOutOfRangeStampsOrTheMethodOffWhenJudgedThenNothingIsStaleOrReported) {
  InputAge age(AgeMethod::kRelative, kDeadline);
  EXPECT_FALSE(age.judge("imu", "w", INT64_MIN, 10 * kSecond).stale);
  EXPECT_FALSE(age.judge("imu", "w", INT64_MAX, 10 * kSecond).stale);
  EXPECT_FALSE(age.judge("imu", "w", -1, 10 * kSecond).stale);
  InputAge off(AgeMethod::kOff, kDeadline);
  EXPECT_FALSE(off.judge("imu", "w", 0, 100 * kSecond).stale);
  off.fused("imu", 5 * kSecond);
  DiagnosticsReport r;
  off.report(r);
  EXPECT_TRUE(r.counters.empty());
  EXPECT_TRUE(r.metrics.empty());
}

TEST(InputAge, GivenAMethodNameWhenParsedThenKnownNamesRoundTripAndOthersAreRefused) {
  for (const AgeMethod m : {AgeMethod::kRelative, AgeMethod::kHostClock, AgeMethod::kOff}) {
    EXPECT_EQ(parse_age_method(to_string(m)), m);
  }
  try {
    parse_age_method("wall");
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("relative, host_clock, off"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace poise::nodes
