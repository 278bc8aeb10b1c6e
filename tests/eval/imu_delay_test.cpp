// IMU group delay estimation against a reference: synthetic motion with a known delay.
#include "poise/eval/imu_delay.h"

#include "poise/core/attitude.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace poise::eval {
namespace {

constexpr double kRateHz = 2000.0 / 7.0;  // BROAD's rate
constexpr double kDelayToleranceSamples = 0.1;

/// Angular rate of a smooth 3-axis motion at time t (s), rad/s.
Eigen::Vector3d omega_at(double t) {
  return {1.5 * std::sin(2.0 * kPi * 0.7 * t), 1.0 * std::sin(2.0 * kPi * 0.45 * t + 1.0),
          2.0 * std::sin(2.0 * kPi * 0.3 * t + 2.0)};
}

struct Recording {
  std::vector<Eigen::Vector3d> gyro;
  std::vector<Eigen::Vector4d> ref;
  std::vector<uint8_t> use;
};

/// A reference from fine integration of omega_at, and a gyro that reports omega_at(t - delay).
Recording record(double delay_s, double seconds, bool still = false) {
  Recording r;
  const double h = 1.0 / kRateHz;
  const int fine = 20;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  const auto n = static_cast<size_t>(seconds * kRateHz);
  for (size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * h;
    r.ref.emplace_back(q.w(), q.x(), q.y(), q.z());
    r.gyro.push_back(still ? Eigen::Vector3d::Zero() : omega_at(t - delay_s));
    r.use.push_back(1);
    for (int j = 0; j < fine && !still; ++j) {
      q = (q * quat_exp(omega_at(t + (j + 0.5) * h / fine) * (h / fine))).normalized();
    }
  }
  return r;
}

TEST(ImuDelay, GivenAKnownDelayWhenEstimatedThenFoundToATenthOfASample) {
  for (const double delay_samples : {0.0, 1.7, 3.2}) {
    const Recording r = record(delay_samples / kRateHz, 30.0);
    ImuDelayOptions o;
    o.rate_hz = kRateHz;
    const ImuDelayEstimate e = estimate_imu_delay(r.gyro, r.ref, r.use, o);
    ASSERT_TRUE(e.ok) << e.why;
    EXPECT_NEAR(e.delay_samples, delay_samples, kDelayToleranceSamples) << delay_samples;
    EXPECT_NEAR(e.delay_s, e.delay_samples / kRateHz, 1e-12);
    EXPECT_LE(e.rms_at_delay_deg, e.rms_at_zero_deg);
  }
}

TEST(ImuDelay, GivenNoMotionOrNoReferenceWhenEstimatedThenRefusedWithAReason) {
  ImuDelayOptions o;
  o.rate_hz = kRateHz;
  const Recording still = record(0.0, 10.0, true);
  const ImuDelayEstimate a = estimate_imu_delay(still.gyro, still.ref, still.use, o);
  EXPECT_FALSE(a.ok);
  EXPECT_NE(std::string(a.why).find("fewer than 20 windows"), std::string::npos);

  Recording lost = record(0.0, 10.0);
  for (auto& q : lost.ref) {
    q.setConstant(std::nan(""));
  }
  EXPECT_FALSE(estimate_imu_delay(lost.gyro, lost.ref, lost.use, o).ok);

  ImuDelayOptions bad;  // rate 0
  EXPECT_FALSE(estimate_imu_delay(lost.gyro, lost.ref, lost.use, bad).ok);
}

TEST(ImuDelayCli, GivenABroadTrialWhenCalibratedThenPrintsTheDelayAndTheParameterLine) {
  POISE_REQUIRE_SHARED_DIR(shared);
  const auto r = testing::run({testing::bin("poise"), "calibrate", "imu-delay",
                               shared + "/broad/01_undisturbed_slow_rotation_A.hdf5"},
                              std::chrono::seconds(60));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("01_undisturbed_slow_rotation_A"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("median over 1 trials"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("imu_delay_s: 0.00"), std::string::npos) << r.output;
}

TEST(ImuDelayCli, GivenAMissingFileWhenCalibratedThenUsageError) {
  const auto r = testing::run({testing::bin("poise"), "calibrate", "imu-delay", "/nonexistent.hdf5"},
                              std::chrono::seconds(30));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("/nonexistent.hdf5"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace poise::eval
