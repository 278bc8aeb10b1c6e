// The parallel KF's published covariance against the strict chi-square bounds (issue 31), like
// GaussNewtonChiSquare: a simulated sensor at rest whose noise is what the filter's keys say, its
// gyro bias drawn from the filter's own prior (N(0, bias_sigma_init_rps^2 I)), M independent
// runs (seeds); the NEES averaged over the runs at each evaluated instant against the two-sided
// 95 % bounds for 3 M degrees of freedom divided by M (poise/testing/chi_square.h). Oracle: the
// simulator's truth. The instants cover the time the bias is being learnt (the first rest is
// detected after rest_min_s) and the accelerometer low-pass and the heading forget the attitude
// error the unknown bias left in them.
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/sim/sensor_simulator.h"
#include "poise/testing/chi_square.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

namespace poise {
namespace {

constexpr int kRuns = 50;         // independent seeds
constexpr double kRateHz = 200.0;  // sample rate, Hz
constexpr double kFirstS = 2.0;   // evaluated instants: from (the bias still unknown), s
constexpr double kLastS = 12.0;   // ... to (the scenario's first magnet comes at 15 s), s
constexpr double kEveryS = 0.5;   // ... every, s
// While the bias is learnt (the rest is detected after about 2 s) and the low-pass carries what
// the unknown bias left (2-4 s), each instant's average lies outside its two-sided 95 % bounds with
// probability 5 %: of those 5 instants at most 1 may (P(more | consistent) = 2.3 %, binomial).
// Later the tilt is conservative (averaged tilt NEES, 2 dof, 0.26-1.16 over 5-12 s: the
// Butterworth's error crosses zero while the covariance keeps its floor tau^2 P_b, and the
// external-acceleration term's slow gravity reference still lags the frame's turn by the bias
// error the start left), so over all 21 instants only the side a consumer relies on is asserted:
// at most 3 above the upper bound (P(more | consistent) below 1.6 %).
constexpr double kTwoSidedUntilS = 4.0;
constexpr int kMaxOutside = 1;
constexpr int kMaxAbove = 3;
// The heading alone (1 degree of freedom) is consistent at every instant (averaged 0.92-1.01,
// its bias error taken from the bias filter's own error model): two-sided over all 21 instants,
// at most 3 outside (P(more | consistent) = 1.9 %, binomial).
constexpr int kMaxOutsideHeading = 3;

/// The filter told what the simulated sensor is (its keys describe the sensor): the heading's
/// gyro and magnetometer noise per sample, the simulator's gravity and Earth field (known, as
/// GaussNewtonChiSquare's), no gyro scale error, no delay; and the simulator's bias a random walk
/// of the density the filter's drift keys give (bias_drift_rps per sqrt(bias_forgetting_time_s)).
ParallelKfParams told_the_simulated_sensor(const sim::SimConfig& cfg) {
  ParallelKfParams p = ParallelKfParams::defaults();
  p.tilt.gravity_mps2 = cfg.gravity_mps2;
  p.sigma_gyro_heading_rps = cfg.noise.sigma_gyro_rps;
  p.sigma_mag_ut = cfg.noise.sigma_mag_ut;
  p.motion_gyro_scale_error = 0.0;
  p.field_magnitude_ut = cfg.field.magnitude_ut;
  p.dip_deg = cfg.field.dip_deg;
  p.imu_delay_s = 0.0;  // the simulator's samples are at their stamps
  return p;
}

TEST(ParallelKfChiSquare, GivenASensorAtRestWithKnownNoiseAndABiasFromThePriorWhenRunManyTimesThenTheAveragedNeesLiesInsideTheChiSquareBounds) {
  const int instants = static_cast<int>((kLastS - kFirstS) / kEveryS + 0.5) + 1;
  std::vector<double> sum(static_cast<size_t>(instants), 0.0);
  std::vector<double> sum_tilt(static_cast<size_t>(instants), 0.0);
  std::vector<double> sum_head(static_cast<size_t>(instants), 0.0);
  for (int run = 0; run < kRuns; ++run) {
    // GIVEN the simulator's static scenario with a bias drawn from the filter's prior
    sim::SimConfig cfg = sim::make_scenario("static_magnet", kRateHz, 2000 + static_cast<uint64_t>(run));
    const ParallelKfParams p = told_the_simulated_sensor(cfg);
    std::mt19937_64 rng(7000 + static_cast<uint64_t>(run));
    std::normal_distribution<double> bias(0.0, p.bias_sigma_init_rps);
    cfg.noise.gyro_bias_rps = Eigen::Vector3d(bias(rng), bias(rng), bias(rng));
    cfg.noise.gyro_bias_walk_rps_per_sqrt_s = p.bias_drift_rps / std::sqrt(p.bias_forgetting_time_s);
    ParallelKf kf(p);
    sim::SensorSimulator simu(cfg);
    int next = 0;
    // WHEN the filter runs over every sample
    while (!simu.done() && next < instants) {
      const sim::SimSample s = simu.next();
      const bool ok = kf.update(s.imu);
      if (ok && s.truth.t_s >= kFirstS + next * kEveryS) {
        const ParallelKfOutput out = kf.output();
        const Eigen::Vector3d e = world_attitude_error(out.q_world_body, s.truth.q_world_body);
        const Eigen::Matrix3d cov = kf.attitude_covariance(out);
        const auto i = static_cast<size_t>(next);
        sum[i] += attitude_nees(e, cov);
        const Eigen::Vector2d et = e.head<2>();
        sum_tilt[i] += et.dot(cov.topLeftCorner<2, 2>().ldlt().solve(et));
        sum_head[i] += e.z() * e.z() / cov(2, 2);
        ++next;
      }
    }
    ASSERT_EQ(next, instants) << "run " << run;
  }
  // THEN the NEES averaged over the runs lies inside the bounds at all but a few instants
  const testing::AveragedNeesBounds b = testing::averaged_nees_bounds_95(3, kRuns);
  const testing::AveragedNeesBounds bh = testing::averaged_nees_bounds_95(1, kRuns);
  int outside = 0;
  int above = 0;
  int outside_heading = 0;
  double mean = 0.0;
  for (int i = 0; i < instants; ++i) {
    const auto k = static_cast<size_t>(i);
    const double avg = sum[k] / kRuns;
    mean += avg / instants;
    if (kFirstS + i * kEveryS <= kTwoSidedUntilS + 1e-9) {
      outside += avg < b.lo || avg > b.hi ? 1 : 0;
    }
    above += avg > b.hi ? 1 : 0;
    const double avg_head = sum_head[k] / kRuns;
    outside_heading += avg_head < bh.lo || avg_head > bh.hi ? 1 : 0;
    std::printf("t %5.1f s: averaged NEES %.3f (tilt, 2 dof, %.3f; heading, 1 dof, %.3f)\n", kFirstS + i * kEveryS,
                avg, sum_tilt[k] / kRuns, sum_head[k] / kRuns);
  }
  std::printf("parallel KF, %d runs: averaged NEES bounds [%.3f, %.3f], mean over %d instants %.3f, %d outside "
              "until %.0f s, %d above\n",
              kRuns, b.lo, b.hi, instants, mean, outside, kTwoSidedUntilS, above);
  std::printf("heading alone: bounds [%.3f, %.3f], %d of %d instants outside\n", bh.lo, bh.hi, outside_heading,
              instants);
  EXPECT_LE(outside, kMaxOutside);
  EXPECT_LE(above, kMaxAbove);
  EXPECT_LE(outside_heading, kMaxOutsideHeading);
}

}  // namespace
}  // namespace poise
