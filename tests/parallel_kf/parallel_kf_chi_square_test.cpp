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
#include "poise/testing/averaged_nees.h"
#include "poise/testing/chi_square.h"
#include "poise/testing/rotated_field.h"
#include "told_sensor.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
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
// probability 5 %: of those 5 instants at most 1 may (P(more | consistent) = 2.3 %, binomial;
// measured: none, 2.39-2.46, the tilt 2.03-2.16 for 2 dof; session 16: 2.41-2.69, the tilt
// 2.13-2.34, when the bias error before the first rest was under-counted). Later the tilt is conservative
// (averaged tilt NEES, 2 dof, 0.66-1.84 over 5-12 s: the Butterworth's error crosses zero while the
// covariance keeps its floor tau^2 P_b), so over all 21 instants only the side a consumer relies
// on is asserted: at most 3 above the upper bound (P(more | consistent) below 1.6 %).
constexpr double kTwoSidedUntilS = 4.0;
constexpr int kMaxOutside = 1;
constexpr int kMaxAbove = 3;
// The heading alone (1 degree of freedom) is consistent at every instant (averaged 0.80-1.07,
// its bias error taken from the bias filter's own error model, the field term's dip measured
// against the accepted dips so that it no longer reads the tilt error): two-sided over all 21 instants,
// at most 3 outside (P(more | consistent) = 1.9 %, binomial).
constexpr int kMaxOutsideHeading = 3;

/// One run of `cfg` through a filter with `p`, its NEES added to `a` at each of a's instants.
void add_run(const sim::SimConfig& cfg, const ParallelKfParams& p, testing::AveragedNees& a) {
  ParallelKf kf(p);
  sim::SensorSimulator simu(cfg);
  // WHEN the filter runs over every sample
  const int reached = a.add_run(
      simu, [&](const sim::SimSample& s) { return kf.update(s.imu); },
      [&](const sim::SimSample& s, Eigen::Vector3d& e, Eigen::Matrix3d& cov) {
        const ParallelKfOutput out = kf.output();
        e = world_attitude_error(out.q_world_body, s.truth.q_world_body);
        cov = kf.attitude_covariance(out);
      });
  EXPECT_EQ(reached, a.instants()) << cfg.name << " seed " << cfg.seed;
}

/// A gyro bias drawn from N(0, sd^2 I), rad/s.
Eigen::Vector3d bias_drawn(double sd, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> bias(0.0, sd);
  return Eigen::Vector3d(bias(rng), bias(rng), bias(rng));
}

/// A gyro bias drawn from the filter's prior N(0, bias_sigma_init_rps^2 I).
Eigen::Vector3d bias_from_the_prior(const ParallelKfParams& p, uint64_t seed) {
  return bias_drawn(p.bias_sigma_init_rps, seed);
}

/// The filter told every figure of the simulated sensor (told_the_simulated_sensor, its bias walk
/// and its white noise density), and the sensor's bias drawn from the filter's prior (`bias_seed`).
ParallelKfParams told_every_figure(sim::SimConfig& cfg, uint64_t bias_seed) {
  ParallelKfParams p = told_the_simulated_sensor(cfg);
  p.gyro_bias_walk_rps_per_sqrt_s = cfg.noise.gyro_bias_walk_rps_per_sqrt_s;
  p.gyro_noise_density_rps_per_sqrt_hz = cfg.noise.sigma_gyro_rps / std::sqrt(cfg.rate_hz);
  cfg.noise.gyro_bias_rps = bias_from_the_prior(p, bias_seed);
  return p;
}

/// kRuns runs of the static scenario, each with a bias drawn from the filter's prior walking at
/// `sensor_walk` (rad/s/sqrt(s)); the filter told the sensor (told_the_simulated_sensor) and,
/// unless NaN, that walk as gyro_bias_walk_rps_per_sqrt_s.
/// `learn_field`: the field reference (magnitude, dip) not told, learnt at start-up; from
/// `first_s` (s). `bias_sd` (rad/s): the spread the biases are drawn from instead of the prior,
/// and `told_bias_sd` what the filter is told of it (gyro_initial_bias_sd_rps; NaN: not told).
testing::AveragedNees run_at_rest(double sensor_walk, double told_walk, bool learn_field = false,
                                  double first_s = kFirstS, double bias_sd = std::nan(""),
                                  double told_bias_sd = std::nan("")) {
  testing::AveragedNees a(first_s, kLastS, kEveryS, kRuns);
  for (int run = 0; run < kRuns; ++run) {
    // GIVEN the simulator's static scenario with a bias drawn from the filter's prior
    sim::SimConfig cfg = sim::make_scenario("static_magnet", kRateHz, 2000 + static_cast<uint64_t>(run));
    ParallelKfParams p = told_the_simulated_sensor(cfg);
    p.gyro_bias_walk_rps_per_sqrt_s = told_walk;
    if (learn_field) {
      p.field_magnitude_ut = std::nan("");
      p.dip_deg = std::nan("");
    }
    p.gyro_initial_bias_sd_rps = told_bias_sd;
    cfg.noise.gyro_bias_rps =
        bias_drawn(std::isnan(bias_sd) ? p.bias_sigma_init_rps : bias_sd, 7000 + static_cast<uint64_t>(run));
    cfg.noise.gyro_bias_walk_rps_per_sqrt_s = sensor_walk;
    add_run(cfg, p, a);
  }
  return a;
}

TEST(ParallelKfChiSquare, GivenASensorAtRestWithKnownNoiseAndABiasFromThePriorWhenRunManyTimesThenTheAveragedNeesLiesInsideTheChiSquareBounds) {
  // (the simulator's bias a random walk of the density the filter's drift keys give, the filter
  // not told it: the design drift is then taken as the sensor's)
  const testing::AveragedNees a =
      run_at_rest(ParallelKfParams{}.bias_drift_rps / std::sqrt(ParallelKfParams{}.bias_forgetting_time_s), std::nan(""));
  // THEN the NEES averaged over the runs lies inside the bounds at all but a few instants
  const testing::AveragedNeesBounds b = testing::averaged_nees_bounds_95(3, kRuns);
  const testing::AveragedNeesBounds bh = testing::averaged_nees_bounds_95(1, kRuns);
  const int outside = a.outside(a.total, b, kTwoSidedUntilS);
  const int above = a.above(a.total, b.hi);
  const int outside_heading = a.outside(a.heading, bh);
  a.print();
  std::printf("parallel KF, %d runs: averaged NEES bounds [%.3f, %.3f], %d outside until %.0f s, %d above, of %d\n",
              kRuns, b.lo, b.hi, outside, kTwoSidedUntilS, above, a.instants());
  std::printf("heading alone: bounds [%.3f, %.3f], %d of %d instants outside\n", bh.lo, bh.hi, outside_heading,
              a.instants());
  EXPECT_LE(outside, kMaxOutside);
  EXPECT_LE(above, kMaxAbove);
  EXPECT_LE(outside_heading, kMaxOutsideHeading);
}

// The same rest with the field reference learnt at start-up (not told): the heading is unknown
// (a provisional reference, variance pi^2 / 3) until the reference is verified, startup_s +
// mag_verify_s = 6 s, so the heading alone is evaluated from 6.5 s, two-sided at each of its 12
// instants: at most 2 outside (P(more | consistent) = 2.0 %, binomial). The learnt reference holds
// the tilt error of its learning window (the bias still unknown), which the field term's dip
// deviation reads; this guards the heading against a covariance that leans on it (measured:
// 0.79-1.19, none outside; the field term's reference weighted by the tilt variance alone and the
// bias error before the first rest under-counted, session 16: 1.46-1.69 at 6.5-9 s).
constexpr double kLearntFirstS = 6.5;
constexpr int kMaxOutsideLearnt = 2;

TEST(ParallelKfChiSquare, GivenASensorAtRestWhoseFieldReferenceIsLearntWhenRunManyTimesThenTheHeadingsAveragedNeesLiesInsideTheChiSquareBoundsOnceItIsKnown) {
  const ParallelKfParams d;
  const testing::AveragedNees a =
      run_at_rest(d.bias_drift_rps / std::sqrt(d.bias_forgetting_time_s), std::nan(""), true, kLearntFirstS);
  const testing::AveragedNeesBounds bh = testing::averaged_nees_bounds_95(1, kRuns);
  const int outside_heading = a.outside(a.heading, bh);
  a.print();
  std::printf("learnt field, heading alone: bounds [%.3f, %.3f], %d of %d instants outside\n", bh.lo, bh.hi,
              outside_heading, a.instants());
  // THEN the heading alone lies inside its bounds at all but a few instants
  EXPECT_LE(outside_heading, kMaxOutsideLearnt);
}

// The gyro's bias at start (gyro_initial_bias_sd_rps, a property of the sensor) against the bias
// filter's design prior (bias_sigma_init_rps, 0.5 deg/s): a sensor whose biases are drawn with a
// spread kSensorBiasSdDeg, under a third of it. Until the first rest has measured the bias
// (about 2 s) the attitude drifts by it, and the lags forget that error over seconds (tilt) and
// tens of seconds (heading); the published covariance carries it from the bias error's variance at
// start. Oracle: the simulator's truth; a consistent filter's averaged NEES is 3 (heading alone 1).
// Not told, the filter takes its prior as the sensor's spread: its covariance is about 7 times too
// large (measured: averaged NEES 0.37-0.52 at 2-4 s, heading 0.10-0.16 throughout). Told, it is
// nearer consistency at every instant (measured 2.21-2.99, heading 0.51-0.89) and never
// overconfident; it stays somewhat conservative (3 of the 5 instants until 4 s just under the lower
// bound, 2.21-2.29 against 2.36, and the heading under it from 9.5 s) because the floors that do
// not depend on the start (tau^2 P_b, P_b,z t^2: the first test) keep their size while the error
// the start leaves shrinks with the spread.
constexpr double kSensorBiasSdDeg = 0.15;  // deg/s

/// |log(v / consistent)|: how far an averaged NEES is from a consistent filter's, as a ratio.
double log_distance(double v, double consistent) { return std::abs(std::log(v / consistent)); }

TEST(ParallelKfChiSquare, GivenAGyroWhoseBiasAtStartSpreadsLessThanTheDesignPriorWhenTheFilterIsToldTheSpreadThenItsAveragedNeesIsNearerConsistencyAndNeverAboveTheBound) {
  const ParallelKfParams d;
  const double walk = d.bias_drift_rps / std::sqrt(d.bias_forgetting_time_s);
  const double sd = kSensorBiasSdDeg * kRadPerDeg;
  const testing::AveragedNees told = run_at_rest(walk, std::nan(""), false, kFirstS, sd, sd);
  const testing::AveragedNees not_told = run_at_rest(walk, std::nan(""), false, kFirstS, sd);
  const testing::AveragedNeesBounds b = testing::averaged_nees_bounds_95(3, kRuns);
  const testing::AveragedNeesBounds bh = testing::averaged_nees_bounds_95(1, kRuns);
  int nearer = 0;
  int nearer_heading = 0;
  for (int i = 0; i < told.instants(); ++i) {
    const auto k = static_cast<size_t>(i);
    nearer += log_distance(told.total[k], 3.0) < log_distance(not_told.total[k], 3.0) ? 1 : 0;
    nearer_heading += log_distance(told.heading[k], 1.0) < log_distance(not_told.heading[k], 1.0) ? 1 : 0;
    std::printf("t %5.1f s: averaged NEES told %.3f (heading %.3f), not told %.3f (heading %.3f)\n", told.instant_s(i),
                told.total[k], told.heading[k], not_told.total[k], not_told.heading[k]);
  }
  const int above = told.above(told.total, b.hi);
  const int above_heading = told.above(told.heading, bh.hi);
  std::printf("bias sd %.2f deg/s: bounds [%.3f, %.3f], heading [%.3f, %.3f]; told nearer 3 at %d (heading %d) of %d "
              "instants, %d (heading %d) above; %d outside until %.0f s\n",
              kSensorBiasSdDeg, b.lo, b.hi, bh.lo, bh.hi, nearer, nearer_heading, told.instants(), above, above_heading,
              told.outside(told.total, b, kTwoSidedUntilS), kTwoSidedUntilS);
  // THEN told, nearer a consistent filter at every instant, and never overconfident
  EXPECT_EQ(nearer, told.instants());
  EXPECT_EQ(nearer_heading, told.instants());
  EXPECT_EQ(above, 0);
  EXPECT_EQ(above_heading, 0);
}

// The gyro's own bias walk (gyro_bias_walk_rps_per_sqrt_s, a property of the sensor) against the
// bias filter's design drift: a sensor whose bias walks kWalkTimesDesign times faster than the
// design drift. At rest the bias filter follows it with its design gains (bias_sigma_rest_rps), so
// the bias error grows with the walk; told the walk, the published heading variance grows with
// it. Not told, the filter takes the design drift as the sensor's and claims too much.
constexpr double kWalkTimesDesign = 10.0;
constexpr int kMinAboveNotTold = 4;  // instants of 21 where the filter not told is above the bound

TEST(ParallelKfChiSquare, GivenAGyroWhoseBiasWalksFasterThanTheDesignDriftWhenTheFilterIsToldItsWalkThenItsHeadingIsNeverOverconfidentWhileNotToldItIs) {
  const ParallelKfParams d;
  const double walk = kWalkTimesDesign * d.bias_drift_rps / std::sqrt(d.bias_forgetting_time_s);
  const testing::AveragedNees told = run_at_rest(walk, walk);
  const testing::AveragedNees not_told = run_at_rest(walk, std::nan(""));
  const testing::AveragedNeesBounds bh = testing::averaged_nees_bounds_95(1, kRuns);
  const int above_told = told.above(told.heading, bh.hi);
  const int outside_told = told.outside(told.heading, bh);
  const int above_not_told = not_told.above(not_told.heading, bh.hi);
  for (int i = 0; i < told.instants(); ++i) {
    const auto k = static_cast<size_t>(i);
    std::printf("t %5.1f s: heading averaged NEES told %.3f, not told %.3f (total told %.3f)\n", told.instant_s(i),
                told.heading[k], not_told.heading[k], told.total[k]);
  }
  std::printf("walk %.2e rad/s/sqrt(s): heading bounds [%.3f, %.3f]; told %d above, %d below; not told %d above, "
              "of %d\n",
              walk, bh.lo, bh.hi, above_told, outside_told - above_told, above_not_told, told.instants());
  // THEN told the walk, the heading is never overconfident (measured: 0.61-1.05; below the lower
  // bound at 7-12 s, where the floor P_b,z t^2 is conservative); not told, it claims too much as
  // soon as the walk has moved the bias (measured: above from 9.5 s, 4.1 at 12 s), and at the end
  EXPECT_EQ(above_told, 0);
  EXPECT_GE(above_not_told, kMinAboveNotTold);
  EXPECT_GT(not_told.heading.back(), bh.hi);
}

// In motion (issue 31's oracle): the simulator's random_motion (5 s still, then 30 s of random
// rotation up to 1.2 rad/s per axis and horizontal accelerations up to 3 m/s^2), the filter told
// every figure of the simulated sensor (told_the_simulated_sensor, its bias walk 0 and its white
// gyro noise density), a bias drawn from the prior, kMotionRuns seeds. Oracle: the simulator's
// truth; the NEES averaged over the runs at each instant against the two-sided 95 % bounds.
// Each of the 28 instants lies outside with probability 5 % when the covariance is consistent:
// at most 4 may (P(more | consistent) = 1.4 %, binomial). Measured (session 15): 0 above, 1 below
// (35 s, where the motion ends), mean 3.195; the tilt (2 dof) 1.54-2.42, the heading alone (1 dof)
// 1.14-1.61. Session 14: 0 above, 1 below, mean 2.94, the heading 1.43-1.96 (above its bound 1.57
// late in the run) while the tilt over-counted (0.81-2.06: the 30 s reference's lag of the present
// bias error's turn); the reference with the tilt's ramp lag but without the heading's share of the
// external acceleration: mean 3.42, 1 above; without the in-phase division: mean 4.29, 23 above.
// Before the motion measurements' real noise (the bias error taken as if their design noise were
// real): 13 instants below, mean 2.08, heading 0.24-0.38 at 30-34 s.
constexpr int kMotionRuns = 30;
constexpr int kMaxOutsideMotion = 4;
constexpr double kMotionFirstS = 8.0;  // evaluated from (the motion starts at 5 s), s
constexpr double kMotionLastS = 35.0;  // ... to (the motion ends), s
constexpr double kMotionEveryS = 1.0;  // ... every, s

testing::AveragedNees run_in_motion() {
  testing::AveragedNees a(kMotionFirstS, kMotionLastS, kMotionEveryS, kMotionRuns);
  for (int run = 0; run < kMotionRuns; ++run) {
    // GIVEN random motion on a simulated sensor whose figures the filter is told
    sim::SimConfig cfg = sim::make_scenario("random_motion", kRateHz, 3000 + static_cast<uint64_t>(run));
    cfg.duration_s = kMotionLastS + 0.5;
    const ParallelKfParams p = told_every_figure(cfg, 9000 + static_cast<uint64_t>(run));
    add_run(cfg, p, a);
  }
  return a;
}

TEST(ParallelKfChiSquare, GivenRandomMotionOnASensorWhoseFiguresTheFilterIsToldWhenRunManyTimesThenTheAveragedNeesLiesInsideTheChiSquareBounds) {
  const testing::AveragedNees a = run_in_motion();
  const testing::AveragedNeesBounds b = testing::averaged_nees_bounds_95(3, kMotionRuns);
  const int outside = a.outside(a.total, b);
  const int above = a.above(a.total, b.hi);
  double mean = 0.0;
  for (const double x : a.total) {
    mean += x / a.instants();
  }
  a.print();
  std::printf("random motion, %d runs: bounds [%.3f, %.3f], mean %.3f, %d above, %d below, of %d\n", kMotionRuns, b.lo,
              b.hi, mean, above, outside - above, a.instants());
  // THEN the averaged NEES lies inside the bounds at all but a few instants
  EXPECT_LE(outside, kMaxOutsideMotion);
}


// A field whose horizontal direction turns where the sensor goes (issue 31; BROAD trial 30): the
// sensor carried back and forth past steel, the field's horizontal direction turning by up to
// kRotationDeg and back with period kRotationPeriodS, its norm and dip unchanged, so the gate
// accepts every field. KF2 follows the field with its lag (about 13 s here), so the heading error
// is the rotation low-passed over it (about a quarter of kRotationDeg: the rotation varies faster
// than the lag, the premise field_rotation_step's factor 2 is derived on; a rotation slower than
// the lag is covered in part, one held for longer than it not at all, docs/ESTIMATORS.md). The random motion of run_in_motion,
// the filter told the sensor; oracle: the simulator's truth (the undisturbed field's north). The
// heading's NEES (1 dof) averaged over the runs against its upper 95 % bound at each instant;
// each lies above it with probability 2.5 % when the covariance covers the error: at most
// kMaxAboveRotated of the instants may (P(more | consistent) below 1 %, binomial). Control: the
// same runs' heading variance without the rotation KF2's innovations show (field_rotation_step)
// lies above the bound at kMinAboveControl instants or more: the rotation is material against the
// rest of the covariance.
constexpr double kRotationDeg = 10.0;      // the field's horizontal rotation, amplitude, deg
constexpr double kRotationPeriodS = 20.0;  // its period, s
constexpr double kRotationStartS = 20.0;   // it begins (the field reference learnt and settled), s
constexpr double kRotatedFirstS = 30.0;    // evaluated instants: from, s
constexpr double kRotatedLastS = 140.0;    // ... to, s
constexpr double kRotatedEveryS = 2.0;     // ... every, s
constexpr int kRotatedRuns = 20;

TEST(ParallelKfChiSquare, GivenAFieldWhoseHorizontalDirectionTurnsWhereTheSensorMovesWhenRunManyTimesThenTheHeadingsAveragedNeesStaysBelowItsChiSquareBound) {
  testing::AveragedNees a(kRotatedFirstS, kRotatedLastS, kRotatedEveryS, kRotatedRuns);
  testing::AveragedNees control(kRotatedFirstS, kRotatedLastS, kRotatedEveryS, kRotatedRuns);
  for (int run = 0; run < kRotatedRuns; ++run) {
    // GIVEN random motion in a field turning horizontally by up to kRotationDeg
    sim::SimConfig cfg = sim::make_scenario("random_motion", kRateHz, 4000 + static_cast<uint64_t>(run));
    cfg.duration_s = kRotatedLastS + 0.5;
    const ParallelKfParams p = told_every_figure(cfg, 11000 + static_cast<uint64_t>(run));
    ParallelKf kf(p);
    testing::RotatedFieldSim simu(cfg, {kRotationDeg * kRadPerDeg, kRotationPeriodS, kRotationStartS});
    // WHEN the filter runs over every sample
    int next = 0;
    while (!simu.done() && next < a.instants()) {
      const sim::SimSample s = simu.next();
      if (kf.update(s.imu) && s.truth.t_s >= a.instant_s(next)) {
        const ParallelKfOutput out = kf.output();
        const Eigen::Vector3d e = world_attitude_error(out.q_world_body, s.truth.q_world_body);
        const Eigen::Matrix3d cov = kf.attitude_covariance(out);
        Eigen::Matrix3d without = cov;
        without(2, 2) -= kf.field_rotation_var();
        a.add(next, e, cov);
        control.add(next++, e, without);
      }
    }
    const int reached = next;
    EXPECT_EQ(reached, a.instants()) << "seed " << cfg.seed;
  }
  const testing::AveragedNeesBounds b = testing::averaged_nees_bounds_95(1, kRotatedRuns);
  a.print();
  double mean = 0.0;
  double mean_control = 0.0;
  for (int i = 0; i < a.instants(); ++i) {
    mean += a.heading[static_cast<size_t>(i)] / a.instants();
    mean_control += control.heading[static_cast<size_t>(i)] / a.instants();
  }
  std::printf("rotated field, %d runs: heading bound %.3f, mean over the instants %.3f, %d above (without the "
              "rotation term: mean %.3f, %d above), of %d\n",
              kRotatedRuns, b.hi, mean, a.above(a.heading, b.hi), mean_control,
              control.above(control.heading, b.hi), a.instants());
  // THEN the heading's NEES averaged over the runs and the instants stays below the bound, where
  // without the rotation the innovations show it does not
  EXPECT_LE(mean, b.hi);
  EXPECT_GT(mean_control, b.hi);
}

}  // namespace
}  // namespace poise
