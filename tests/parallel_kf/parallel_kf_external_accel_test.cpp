// The parallel KF's published tilt covariance under an external acceleration (issue 31): only a
// horizontal acceleration tilts the estimate (the accelerometer's low-passed direction leans
// towards it by a_h / g); a vertical one changes the magnitude only. Oracle: a level sensor whose
// samples are built here from a known acceleration (body = world, ENU), with white noise of the
// simulator's densities; the error is the estimate's against the identity.
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/parallel_kf/parallel_kf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

namespace poise {
namespace {

constexpr double kRateHz = 200.0;          // sample rate, Hz
constexpr double kDurationS = 120.0;       // run length, s
constexpr double kFromS = 40.0;            // evaluated from (start-up, bias and reference settled), s
constexpr double kAccelMps2 = 1.0;         // acceleration amplitude, m/s^2
constexpr double kAccelFreqHz = 0.05;      // its frequency (inside the tilt low-pass's band), Hz
constexpr double kFieldUt = 50.0;          // Earth field, uT
constexpr double kDipDeg = 60.0;           // its dip, deg
constexpr double kSigmaGyroRps = 0.05 * kRadPerDeg;  // white noise per sample (the simulator's)
constexpr double kSigmaAccelMps2 = 0.04;
constexpr double kSigmaMagUt = 0.2;
// A horizontal acceleration: the tilt error (about 5 deg here) is covered: at least this share of
// the evaluated samples has a tilt NEES (2 dof) inside its 95 % bound 5.991 (the sinusoid's error
// is deterministic, so not a chi-square draw: the figure asserted is the coverage)
constexpr double kMinInsideHorizontal = 0.90;
// A vertical one of the same size does not tilt: the published tilt sigma stays below this,
// where the old term (the magnitude's deviation read as a horizontal acceleration) gave about
// 0.9 a / g = 5 deg, deg
constexpr double kMaxTiltSigmaVerticalDeg = 0.5;
constexpr double kChi2Dof2P95 = 5.991;
// A static sensor with an unknown gyro bias: the almost inertial frame turns by it until rest has
// taught it (about 0.5 deg/s for 2 s here: 1 deg), and the gravity reference of the
// external-acceleration term (30 s) held that turn as a horizontal acceleration for a minute, and
// the noise of the first sample it started on (0.35 deg here; measured 0.20-0.37 deg from 6 to
// 20 s before). Each bias change now turns it into the new bias's frame and it starts as the mean
// of the samples so far: nothing accelerates, so from kStaticFromS (the twin low-pass has
// forgotten the start) the term's tilt sigma stays below kMaxExternalAccelSigmaStaticDeg, deg.
// Session 15: the reference is three stages of 10 s, each the mean of its samples until it holds
// 10 s of them, whose combination reaches its ramp lag as their lags fill (about two stage time
// constants): evaluated from 20 s (measured: 0.056 deg at 15 s, 0.043 at 20 s, at most 0.027 from
// 25 s; session 13's first-order reference 0.039 from 15 s).
constexpr double kStaticFromS = 20.0;
constexpr double kMaxExternalAccelSigmaStaticDeg = 0.05;
// A static sensor whose gyro bias the filter does not learn (bias_estimation off): the almost
// inertial frame turns steadily at the bias, a ramp, which the tilt's low-pass lags by its tau and
// so does the reference (session 15): the term stays below kMaxExternalAccelSigmaStaticDeg from
// kSteadyFromS (the reference's stages full, their lags settled: several of their 10 s), while the
// tilt's real error is the low-pass's lag of the ramp, tau |b_h| (the oracle: 0.17 deg here). A
// first-order reference of 30 s lagged it by 27 s more and held (30 - tau) |b_h| = 1.6 deg.
const Eigen::Vector3d kUnlearntBiasRps = Eigen::Vector3d(0.05, -0.03, 0.0) * kRadPerDeg;
constexpr double kSteadyFromS = 60.0;
constexpr double kLagTolerance = 0.2;  // relative, on the tilt error's largest value against tau |b_h|

struct AccelRun {
  double inside = 0.0;          ///< share of evaluated samples with tilt NEES <= 5.991
  double max_tilt_err_deg = 0.0;
  double max_tilt_sigma_deg = 0.0;
  double max_external_accel_sigma_deg = 0.0;  ///< the external-acceleration term's tilt sigma
};

/// A level sensor accelerated along `axis` (amplitude kAccelMps2; zero: static) with a constant
/// gyro bias `bias_rps` (learnt by the filter unless `learn_bias` is false), evaluated from `from_s`.
AccelRun run(const Eigen::Vector3d& axis, const Eigen::Vector3d& bias_rps = Eigen::Vector3d::Zero(),
             double from_s = kFromS, bool learn_bias = true) {
  ParallelKfParams p = ParallelKfParams::defaults();
  p.imu_delay_s = 0.0;  // the samples are at their stamps
  p.bias_estimation = learn_bias;
  ParallelKf kf(p);
  std::mt19937_64 rng(31);
  std::normal_distribution<double> n(0.0, 1.0);
  auto noise = [&](double s) { return Eigen::Vector3d(s * n(rng), s * n(rng), s * n(rng)); };
  const double g = p.tilt.gravity_mps2;
  const double dip = kDipDeg * kRadPerDeg;
  const Eigen::Vector3d field(0.0, kFieldUt * std::cos(dip), -kFieldUt * std::sin(dip));
  AccelRun r;
  int evaluated = 0;
  int inside = 0;
  const int samples = static_cast<int>(kDurationS * kRateHz);
  for (int k = 0; k < samples; ++k) {
    const double t = k / kRateHz;
    ImuSample s;
    s.stamp_ns = static_cast<int64_t>(std::llround(t * 1e9));
    s.seq = static_cast<uint32_t>(k);
    const double a = kAccelMps2 * std::sin(2.0 * M_PI * kAccelFreqHz * t);
    s.accel_mps2 = Eigen::Vector3d(0.0, 0.0, g) + a * axis + noise(kSigmaAccelMps2);
    s.gyro_rps = bias_rps + noise(kSigmaGyroRps);
    s.mag_ut = field + noise(kSigmaMagUt);
    s.has_mag = true;
    EXPECT_TRUE(kf.update(s));
    if (t < from_s) {
      continue;
    }
    const ParallelKfOutput out = kf.output();
    const Eigen::Vector3d e = world_attitude_error(out.q_world_body, Eigen::Quaterniond::Identity());
    const Eigen::Matrix2d tilt = kf.attitude_covariance(out).topLeftCorner<2, 2>();
    const Eigen::Vector2d et = e.head<2>();
    ++evaluated;
    inside += et.dot(tilt.ldlt().solve(et)) <= kChi2Dof2P95 ? 1 : 0;
    r.max_tilt_err_deg = std::max(r.max_tilt_err_deg, et.norm() / kRadPerDeg);
    r.max_tilt_sigma_deg = std::max(r.max_tilt_sigma_deg, std::sqrt(tilt.trace()) / kRadPerDeg);
    const Eigen::Matrix3d ext = kf.covariance_terms(out).external_accel;
    r.max_external_accel_sigma_deg =
        std::max(r.max_external_accel_sigma_deg, std::sqrt(ext(0, 0) + ext(1, 1)) / kRadPerDeg);
  }
  r.inside = static_cast<double>(inside) / evaluated;
  return r;
}

TEST(ParallelKfExternalAccel, GivenAHorizontalAccelerationWhenTheTiltLeansWithItThenThePublishedTiltCovarianceCoversTheError) {
  // GIVEN a level sensor accelerated east and west, WHEN filtered
  const AccelRun r = run(Eigen::Vector3d::UnitX());
  std::printf("horizontal: largest tilt error %.2f deg, largest tilt sigma %.2f deg, %.1f %% inside\n",
              r.max_tilt_err_deg, r.max_tilt_sigma_deg, 100.0 * r.inside);
  // THEN the tilt leans (the scenario is what it says) and the published tilt covers it
  EXPECT_GT(r.max_tilt_err_deg, 2.0);
  EXPECT_GE(r.inside, kMinInsideHorizontal);
}

TEST(ParallelKfExternalAccel, GivenAVerticalAccelerationWhenOnlyTheMagnitudeChangesThenTheTiltCovarianceDoesNotGrow) {
  // GIVEN the same acceleration up and down, WHEN filtered
  const AccelRun r = run(Eigen::Vector3d::UnitZ());
  std::printf("vertical: largest tilt error %.3f deg, largest tilt sigma %.3f deg, %.1f %% inside\n",
              r.max_tilt_err_deg, r.max_tilt_sigma_deg, 100.0 * r.inside);
  // THEN the tilt does not lean, and neither does its published sigma grow
  EXPECT_LT(r.max_tilt_err_deg, kMaxTiltSigmaVerticalDeg);
  EXPECT_LT(r.max_tilt_sigma_deg, kMaxTiltSigmaVerticalDeg);
}

TEST(ParallelKfExternalAccel, GivenAStaticSensorWithAnUnknownGyroBiasWhenRestTeachesItThenTheExternalAccelerationTermStaysNearZero) {
  // GIVEN a static, level sensor whose gyro has a bias the filter learns at rest (a turn of the
  // almost inertial frame of about 1 deg before it is learnt)
  const Eigen::Vector3d bias = Eigen::Vector3d(0.4, -0.3, 0.2) * kRadPerDeg;
  // WHEN filtered
  const AccelRun r = run(Eigen::Vector3d::Zero(), bias, kStaticFromS);
  std::printf("static with a gyro bias: external-acceleration tilt sigma at most %.4f deg from %.0f s, tilt error "
              "at most %.3f deg\n",
              r.max_external_accel_sigma_deg, kStaticFromS, r.max_tilt_err_deg);
  // THEN the term the reference gives stays near zero: no acceleration, and no turn of the frame
  EXPECT_LT(r.max_external_accel_sigma_deg, kMaxExternalAccelSigmaStaticDeg);
}

TEST(ParallelKfExternalAccel, GivenAGyroBiasTheFilterDoesNotLearnWhenTheFrameTurnsSteadilyThenTheExternalAccelerationTermStaysNearZero) {
  // GIVEN a static, level sensor whose gyro bias is never learnt (the frame turns at it steadily)
  // WHEN filtered
  const AccelRun r = run(Eigen::Vector3d::Zero(), kUnlearntBiasRps, kSteadyFromS, false);
  const double lag_deg = ParallelKfParams::defaults().accel_lowpass_tau_s * kUnlearntBiasRps.head<2>().norm() / kRadPerDeg;
  std::printf("unlearnt bias: tilt error at most %.3f deg (tau |b_h| %.3f deg), external-acceleration tilt sigma at "
              "most %.4f deg from %.0f s\n",
              r.max_tilt_err_deg, lag_deg, r.max_external_accel_sigma_deg, kSteadyFromS);
  // THEN the tilt lags the turn by the low-pass's tau (the scenario is what it says), and the term,
  // which the reference would have held as an acceleration, stays near zero: nothing accelerates
  EXPECT_NEAR(r.max_tilt_err_deg, lag_deg, kLagTolerance * lag_deg);
  EXPECT_LT(r.max_external_accel_sigma_deg, kMaxExternalAccelSigmaStaticDeg);
}

}  // namespace
}  // namespace poise
