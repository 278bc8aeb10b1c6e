// The selective EKF's published covariance against the strict chi-square bounds (issue 31), like
// ParallelKfChiSquare: a simulated sensor at rest whose noise densities the filter is told (the
// figures of the sensor: gyro_noise_density_rps_per_sqrt_hz, accel_noise_density_mps2_per_sqrt_hz,
// gyro_bias_walk_rps_per_sqrt_s; the gains are the defaults'), its gyro bias drawn from the
// filter's own prior (N(0, init_sigma_bias_rps^2 I)), M independent runs (seeds); the NEES
// averaged over the runs at each evaluated instant against the two-sided 95 % bounds for d M
// degrees of freedom divided by M (poise/testing/chi_square.h). Oracle: the simulator's truth.
// Before the figures of the sensor (P_err from the design densities, counted as white noise), 22 of
// 23 instants lay outside, all conservative (tilt NEES 0.05-0.07 of 2 from 5 s).
#include "poise/core/attitude.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/sim/sensor_simulator.h"
#include "poise/testing/averaged_nees.h"
#include "poise/testing/chi_square.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdio>
#include <random>
#include <vector>

namespace poise {
namespace {

constexpr int kRuns = 50;          // independent seeds
constexpr double kRateHz = 200.0;  // sample rate, Hz
constexpr double kFirstS = 1.0;    // evaluated instants: from, s
constexpr double kLastS = 12.0;    // ... to (the scenario's first magnet comes at 15 s), s
constexpr double kEveryS = 0.5;    // ... every, s
// Each instant's average lies outside its two-sided 95 % bounds with probability 5 % (neighbouring
// instants are correlated). Until kTwoSidedUntilS at most kMaxOutside instants outside (measured:
// none, 2.41-3.17); later the heading turns conservative (averaged 0.43-0.74 for 1 dof from 5.5 s:
// docs/SELECTIVE_EKF.md) and the total with it (2.02-2.35 from 9.5 s), so over all instants
// only the side a consumer relies on is asserted: none above. The tilt (2 dof), what the
// accelerometer's and the gyro's figures set, two-sided over all instants (measured: 1.47-1.70,
// one below).
constexpr double kTwoSidedUntilS = 9.0;
constexpr int kMaxOutside = 1;
constexpr int kMaxAbove = 0;
constexpr int kMaxOutsideTilt = 2;

/// The default filter told the simulated sensor's figures: its white noise densities (per-sample
/// sigma over sqrt(rate)), its bias walk, no gyro scale error; its magnetometer's noise as the
/// heading row's density (one sample fused every aiding_period_s: the density whose variance over
/// that period is the sample's), the simulator's Earth field (known, as ParallelKfChiSquare's) and
/// no delay (its samples are at their stamps). Rest detection off: the zero-rate row's noise,
/// sigma_rest_rate_rps, is a figure of the motion at detected rest (a hand-held device), not of
/// the sensor, and P_err counts it (the simulator's rest is exact: with it on, the tilt is
/// conservative from 5 s, averaged 0.25-0.35 of 2).
SelectiveEkfParams told_the_simulated_sensor(const sim::SimConfig& cfg) {
  SelectiveEkfParams p;
  p.gyro_noise_density_rps_per_sqrt_hz = cfg.noise.sigma_gyro_rps / std::sqrt(kRateHz);
  p.accel_noise_density_mps2_per_sqrt_hz = cfg.noise.sigma_accel_mps2 / std::sqrt(kRateHz);
  p.gyro_bias_walk_rps_per_sqrt_s = cfg.noise.gyro_bias_walk_rps_per_sqrt_s;
  p.gyro_scale_error = 0.0;
  p.field_magnitude_ut = cfg.field.magnitude_ut;
  p.dip_deg = cfg.field.dip_deg;
  p.imu_delay_s = 0.0;
  const double horizontal_ut = cfg.field.magnitude_ut * std::cos(cfg.field.dip_deg * kRadPerDeg);
  p.sigma_heading_rad_sqrt_s = cfg.noise.sigma_mag_ut / horizontal_ut * std::sqrt(p.aiding_period_s);
  p.rest_detection = false;
  return p;
}

/// One run of the filter with `p` over the scenario `cfg`, its world-frame error and published
/// covariance added at each of `a`'s instants; returns the instants reached.
int add_filter_run(testing::AveragedNees& a, const SelectiveEkfParams& p, const sim::SimConfig& cfg) {
  SelectiveEkf ekf(p);
  sim::SensorSimulator simu(cfg);
  return a.add_run(simu, [&](const sim::SimSample& s) { return ekf.update_imu(s.imu); },
                   [&](const sim::SimSample& s, Eigen::Vector3d& e, Eigen::Matrix3d& cov) {
                     e = world_attitude_error(ekf.q_world_body(), s.truth.q_world_body);
                     cov = ekf.attitude_covariance();
                   });
}

testing::AveragedNees run_at_rest() {
  testing::AveragedNees a(kFirstS, kLastS, kEveryS, kRuns);
  for (int run = 0; run < kRuns; ++run) {
    // GIVEN the simulator's static scenario with a bias drawn from the filter's prior
    sim::SimConfig cfg = sim::make_scenario("static_magnet", kRateHz, 3000 + static_cast<uint64_t>(run));
    const SelectiveEkfParams p = told_the_simulated_sensor(cfg);
    std::mt19937_64 rng(9000 + static_cast<uint64_t>(run));
    std::normal_distribution<double> bias(0.0, p.init_sigma_bias_rps);
    cfg.noise.gyro_bias_rps = Eigen::Vector3d(bias(rng), bias(rng), bias(rng));
    // WHEN the filter runs over every sample
    EXPECT_EQ(add_filter_run(a, p, cfg), a.instants()) << "run " << run;
  }
  return a;
}

TEST(SelectiveEkfChiSquare, GivenASensorAtRestWithKnownNoiseDensitiesWhenRunManyTimesThenTheAveragedNeesLiesInsideTheChiSquareBounds) {
  // GIVEN / WHEN: run_at_rest
  const testing::AveragedNees a = run_at_rest();
  const int instants = a.instants();
  const testing::AveragedNeesBounds b = testing::averaged_nees_bounds_95(3, kRuns);
  const testing::AveragedNeesBounds bt = testing::averaged_nees_bounds_95(2, kRuns);
  const testing::AveragedNeesBounds bh = testing::averaged_nees_bounds_95(1, kRuns);
  a.print();
  const int outside = a.outside(a.total, b, kTwoSidedUntilS);
  const int above = a.above(a.total, b.hi);
  const int outside_tilt = a.outside(a.tilt, bt);
  const int outside_heading = a.outside(a.heading, bh);
  std::printf("selective EKF, %d runs: bounds [%.3f, %.3f] (tilt [%.3f, %.3f], heading [%.3f, %.3f]); %d outside "
              "until %.0f s, %d above; tilt %d, heading %d outside of %d instants\n",
              kRuns, b.lo, b.hi, bt.lo, bt.hi, bh.lo, bh.hi, outside, kTwoSidedUntilS, above, outside_tilt,
              outside_heading, instants);
  // THEN the averaged NEES lies inside the bounds (two-sided while the heading is consistent),
  // never above them, and the tilt's inside at all but a few instants
  EXPECT_LE(outside, kMaxOutside);
  EXPECT_LE(above, kMaxAbove);
  EXPECT_LE(outside_tilt, kMaxOutsideTilt);
}

// In motion: random_motion (external accelerations up to 3 m/s^2 from 5 s), the filter told the
// simulated sensor's figures as below but the Earth field and heading density left at their
// defaults (the heading is conservative in motion: the design density; asserted on the tilt).
constexpr int kMoveRuns = 40;
constexpr double kMoveFirstS = 6.0;   ///< s: 1 s into the motion
constexpr double kMoveLastS = 34.0;   ///< s: before the scenario's pause (35 s)
/// s: the tilt's power of the external acceleration's error is low-passed over the tilt's lag
/// (about 3.8 s) after the motion starts at 5 s; from here on it is built up
constexpr double kMoveBuiltUpS = 12.0;
/// of the 23 instants from kMoveBuiltUpS: a consistent filter leaves 5 % of them (1.2) outside the
/// two-sided 95 % bounds by chance, 2.5 % (0.6) above
constexpr int kMaxMoveOutsideTilt = 2;
constexpr int kMaxMoveAboveTilt = 1;

TEST(SelectiveEkfChiSquare, GivenTheSensorFiguresWhenMovingWithExternalAccelerationThenTheTiltsAveragedNeesLiesInsideTheBounds) {
  // GIVEN 40 seeds of the simulator's random motion and the filter told the sensor's figures
  // (noise densities, a constant bias, no scale error, no delay)
  testing::AveragedNees a(kMoveFirstS, kMoveLastS, 1.0, kMoveRuns);
  for (int run = 0; run < kMoveRuns; ++run) {
    const sim::SimConfig cfg = sim::make_scenario("random_motion", kRateHz, 5000 + static_cast<uint64_t>(run));
    SelectiveEkfParams p;
    p.gyro_noise_density_rps_per_sqrt_hz = cfg.noise.sigma_gyro_rps / std::sqrt(kRateHz);
    p.accel_noise_density_mps2_per_sqrt_hz = cfg.noise.sigma_accel_mps2 / std::sqrt(kRateHz);
    p.gyro_bias_walk_rps_per_sqrt_s = cfg.noise.gyro_bias_walk_rps_per_sqrt_s;
    p.gyro_scale_error = 0.0;
    p.imu_delay_s = 0.0;
    // WHEN the filter runs over every sample
    EXPECT_EQ(add_filter_run(a, p, cfg), a.instants()) << "run " << run;
  }
  a.print();
  const testing::AveragedNeesBounds bt = testing::averaged_nees_bounds_95(2, kMoveRuns);
  testing::AveragedNees built_up(kMoveBuiltUpS, kMoveLastS, 1.0, kMoveRuns);
  const auto skip = static_cast<std::ptrdiff_t>(kMoveBuiltUpS - kMoveFirstS + 0.5);
  built_up.tilt.assign(a.tilt.begin() + skip, a.tilt.end());
  const int outside = built_up.outside(built_up.tilt, bt);
  const int above = built_up.above(built_up.tilt, bt.hi);
  std::printf("selective EKF in motion, %d runs: tilt bounds [%.3f, %.3f]; from %.0f s %d outside, %d above of %d "
              "instants; before it %d above\n",
              kMoveRuns, bt.lo, bt.hi, kMoveBuiltUpS, outside, above, built_up.instants(),
              a.above(a.tilt, bt.hi) - above);
  // THEN once the term has built up the tilt's averaged NEES lies inside the two-sided bounds at
  // all but the chance instants (measured: 1 outside, above, at 16 s: 2.693 against 2.666; before
  // it, 1-6 s into the motion, 6 instants above: the power's low-pass still building up)
  EXPECT_LE(outside, kMaxMoveOutsideTilt);
  EXPECT_LE(above, kMaxMoveAboveTilt);
}

}  // namespace
}  // namespace poise
