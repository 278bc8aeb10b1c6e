// The selective EKF (IMU only) started inside a magnetic disturbance (issue 31 "cold start next to
// a magnet"), as ParallelKfColdStart.*: the simulator's tour, the filter's first sample 7 s in, at
// full strength of the magnet brought near (30, 10, -20) uT in the world on a 50 uT / 60 deg field,
// which leaves 5 s later. Oracles: the simulator's truth (the heading error), the published
// covariance's heading variance (it must cover the error all along) and the heading status.
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/testing/cold_start_tour.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace poise {
namespace {

using testing::kTourColdStartS;
using testing::kTourMagnetGoneS;
using testing::kTourSettleS;
constexpr double kMaxHeadingRmsDeg = 2.0;  // the target, deg (the clean start)
// Started in motion, the filter's first sample carries external acceleration, in its attitude and
// in its accelerometer low-pass alike; the bias is a consider state of the tilt rows while the
// low-pass forgets it (aid_accel_tilt.cpp), so it is not learnt from that transient (it was: 4.5 deg
// RMS, bias 1 deg/s off). The bound holds for a start in the magnet too, deg. The published
// heading sigma once verified is asserted by the NEES over the demo's cut (docs), not here.
constexpr double kMaxColdHeadingRmsDeg = 2.0;
// The heading error may never exceed what the published heading sigma admits at 99.7 % for one
// degree of freedom (3 sigma): the filter must not claim to know a heading it has not verified.
constexpr double kCoverSigmas = 3.0;
constexpr double kMinStartErrorDeg = 20.0;  // the start must really be off (else nothing is tested)

TEST(SelectiveEkfColdStart, GivenAStartInsideAMagnetsFieldWhenTheFieldIsCleanThenTheHeadingRestartsAndItsSigmaCoveredTheErrorUntilVerified) {
  // GIVEN the tour from 7 s, inside the first magnet's field
  SelectiveEkf ekf;
  double max_start_err_deg = 0.0;
  double sq = 0.0;
  int n_after = 0;
  int uncovered = 0;
  int samples = 0;
  int unverified = 0;
  bool unverified_in_magnet = true;
  bool verified_at_end = false;
  // WHEN the filter runs from there until the attached magnet
  testing::run_tour_until_attached_magnet(kTourColdStartS, [&](const sim::SimSample& s) {
    const double t = s.truth.t_s;
    if (!ekf.update_imu(s.imu)) {
      return;
    }
    const Eigen::Vector3d e = world_attitude_error(ekf.q_world_body(), s.truth.q_world_body);
    const double heading_err = std::abs(e.z());
    const double sigma = std::sqrt(ekf.attitude_covariance()(2, 2));
    ++samples;
    if (ekf.heading_unknown()) {  // the reference not yet verified
      ++unverified;
      uncovered += heading_err > kCoverSigmas * sigma ? 1 : 0;
    }
    if (t < kTourColdStartS + 1.0) {
      max_start_err_deg = std::max(max_start_err_deg, heading_err * kDegPerRad);
    }
    if (t < kTourMagnetGoneS) {
      unverified_in_magnet = unverified_in_magnet && ekf.heading_status() != HeadingStatus::kVerified;
    }
    if (t >= kTourMagnetGoneS + kTourSettleS) {
      sq += e.z() * e.z();
      ++n_after;
    }
    verified_at_end = ekf.heading_status() == HeadingStatus::kVerified;
  });
  const double rms_deg = std::sqrt(sq / std::max(1, n_after)) * kDegPerRad;
  std::printf("cold start: first-second heading error up to %.1f deg; heading RMS %.3f deg over %d samples from "
              "%.0f s; %d of %d samples before verification (of %d) outside %.0f sigma; relearnt %llu\n",
              max_start_err_deg, rms_deg, n_after, kTourMagnetGoneS + kTourSettleS, uncovered, unverified, samples, kCoverSigmas,
              static_cast<unsigned long long>(ekf.state().field_gate.relearnt));
  // THEN the heading converges once the field is clean, its sigma covered the error all along,
  // and it was unverified while the magnet's field was the reference, verified at the end
  EXPECT_GT(max_start_err_deg, kMinStartErrorDeg) << "the start is inside the disturbance";
  EXPECT_TRUE(unverified_in_magnet) << "never verified while the magnet's field was the reference";
  EXPECT_LT(rms_deg, kMaxColdHeadingRmsDeg);
  EXPECT_EQ(uncovered, 0) << "until verified, the published heading sigma covers the error";
  EXPECT_GE(ekf.state().field_gate.relearnt, 1U);
  EXPECT_TRUE(verified_at_end) << "verified once the clean field has held field_verify_s";
}

// The same tour from its first sample: the field learnt in a clean field is still provisional when
// the magnet comes near at 5 s (accepted for 4 s of the 5 s), yet the magnet's field (78 uT, more
// than the Earth's field anywhere) must not replace it.
TEST(SelectiveEkfColdStart, GivenACleanStartWhenAMagnetComesBeforeTheReferenceIsVerifiedThenItIsNotLearnt) {
  // GIVEN the tour from its start; WHEN the filter runs until the attached magnet
  SelectiveEkf ekf;
  double sq = 0.0;
  int n = 0;
  testing::run_tour_until_attached_magnet(0.0, [&](const sim::SimSample& s) {
    if (!ekf.update_imu(s.imu) || s.truth.t_s < 1.0) {
      return;
    }
    const Eigen::Vector3d e = world_attitude_error(ekf.q_world_body(), s.truth.q_world_body);
    sq += e.z() * e.z();
    ++n;
  });
  const double rms_deg = std::sqrt(sq / std::max(1, n)) * kDegPerRad;
  std::printf("clean start: heading RMS %.3f deg over %d samples, relearnt %llu\n", rms_deg, n,
              static_cast<unsigned long long>(ekf.state().field_gate.relearnt));
  // THEN the reference is kept, the heading accurate and verified
  EXPECT_EQ(ekf.state().field_gate.relearnt, 0U);
  EXPECT_LT(rms_deg, kMaxHeadingRmsDeg);
  EXPECT_EQ(ekf.heading_status(), HeadingStatus::kVerified);
}

}  // namespace
}  // namespace poise

namespace poise {
namespace {

// The mechanism alone: started in motion (the tour 7 s in, handheld, up to 1.5 m/s^2 of external
// acceleration in the first sample), the accelerometer low-pass forgets its first sample over
// accel_lowpass_tau_s; the innovation ramps meanwhile. The bias must not learn that ramp: its error
// may not grow beyond the start's (the filter starts at zero bias; the simulator's is
// (0.3, -0.2, 0.25) deg/s). Before the consider update it reached 1.0 deg/s by 10 s.
TEST(SelectiveEkfColdStart, GivenAStartInMotionWhenTheLowPassForgetsItsFirstSampleThenTheBiasDoesNotLearnTheRamp) {
  constexpr double kBiasGrowthTolDps = 0.05;  // deg/s above the start's bias error
  SelectiveEkf ekf;
  double start_err_dps = -1.0;
  double max_err_dps = 0.0;
  const double until_s = testing::kTourColdStartS + SelectiveEkfParams{}.accel_lowpass_tau_s;
  testing::run_tour_until_attached_magnet(testing::kTourColdStartS, [&](const sim::SimSample& s) {
    if (!ekf.update_imu(s.imu) || s.truth.t_s > until_s) {
      return;
    }
    const double err = (ekf.state().b_rps - s.truth.gyro_bias_rps).norm() * kDegPerRad;
    if (start_err_dps < 0.0) {
      start_err_dps = err;
    }
    max_err_dps = std::max(max_err_dps, err);
  });
  std::printf("start in motion: bias error %.3f deg/s at the start, at most %.3f deg/s until %.1f s\n", start_err_dps,
              max_err_dps, until_s);
  EXPECT_LE(max_err_dps, start_err_dps + kBiasGrowthTolDps);
}

}  // namespace
}  // namespace poise

namespace poise {
namespace {

// The tour's first pause (11-13 s): the rest detector (2 deg/s, 1.5 s still, 0.5 s low-pass) says
// rest from about 13.0 s, as the handheld motion resumes slowly. Oracle: the simulator's bias.
// Before, the zero rate asserted at those samples took their rate as bias: the error grew from
// 0.19 to 0.5 deg/s on z (docs/SELECTIVE_EKF.md). The bias may not get worse across the pause.
TEST(SelectiveEkfColdStart, GivenTheToursPauseWhenTheMotionResumesUnderTheRestDetectorsThresholdThenTheBiasIsNotTakenFromTheRate) {
  constexpr double kBeforeS = 12.9;         // inside the pause, before the detector says rest, s
  constexpr double kAfterS = 14.0;          // the motion resumed 1 s ago, s
  constexpr double kBiasGrowthTolDps = 0.02;  // deg/s per axis above the error before the pause
  SelectiveEkf ekf;
  Eigen::Vector3d before = Eigen::Vector3d::Constant(-1.0);
  Eigen::Vector3d after = Eigen::Vector3d::Constant(-1.0);
  bool rest_seen = false;
  testing::run_tour_until_attached_magnet(testing::kTourColdStartS, [&](const sim::SimSample& s) {
    if (!ekf.update_imu(s.imu)) {
      return;
    }
    const Eigen::Vector3d err = (ekf.state().b_rps - s.truth.gyro_bias_rps).cwiseAbs() * kDegPerRad;
    rest_seen = rest_seen || ekf.state().pre.rest_detector.rest;
    if (s.truth.t_s <= kBeforeS) {
      before = err;
    }
    if (s.truth.t_s <= kAfterS) {
      after = err;
    }
  });
  std::printf("tour pause: bias error %.3f %.3f %.3f deg/s before, %.3f %.3f %.3f deg/s after\n", before.x(),
              before.y(), before.z(), after.x(), after.y(), after.z());
  EXPECT_TRUE(rest_seen) << "the detector said rest at the pause (else nothing is tested)";
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(after[i], before[i] + kBiasGrowthTolDps) << "axis " << i;
  }
}

// The figure on the simulator: the tour from 7 s (inside the magnet) until the attached
// magnet, every sample scored against the truth with the published covariance. The issue asks
// for at least 85 % inside the 95 % ellipsoid (NEES <= 7.815, 3 degrees of freedom); 65.1 % before
// the tilt rows' bias columns and the rest aid's low-pass.
TEST(SelectiveEkfColdStart, GivenAStartInsideAMagnetsFieldWhenScoredAgainstTheTruthThenAtLeast85PercentAreInsideThe95PercentEllipsoid) {
  constexpr double kMinInside = 0.85;  // fraction of samples, the bound
  SelectiveEkf ekf;
  NeesSummary stats;
  testing::run_tour_until_attached_magnet(testing::kTourColdStartS, [&](const sim::SimSample& s) {
    if (ekf.update_imu(s.imu)) {
      stats.add(attitude_nees(world_attitude_error(ekf.q_world_body(), s.truth.q_world_body), ekf.attitude_covariance()));
    }
  });
  std::printf("cold start: %.1f %% of %zu samples inside the 95 %% ellipsoid, median NEES %.2f\n",
              100.0 * stats.fraction_inside(), stats.samples(), stats.median());
  EXPECT_GE(stats.fraction_inside(), kMinInside);
}

}  // namespace
}  // namespace poise
