// ParallelKf with the online hard-iron offset (ParallelKfParams::hard_iron): a tumbling sensor that
// carries a known body-fixed offset, simulated here, and the `hard_iron` YAML keys.
#include "poise/core/consistency.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/sim/sensor_simulator.h"

#include "poise/testing/attached_magnet.h"
#include "poise/testing/param_errors.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <string>

namespace poise {
namespace {

constexpr double kRateHz = 100.0;            // sample rate, Hz
constexpr double kRestS = 3.0;               // at rest before the tumbling starts, s
constexpr double kRunS = 60.0;               // whole run, s
constexpr double kConvergedS = 20.0;         // scored from here on (the estimate needs a few s of motion), s
constexpr double kMagNoiseUt = 0.3;          // 1-sigma per axis, uT
constexpr double kGyroNoiseRps = 0.002;      // 1-sigma per axis, rad/s
constexpr double kAccelNoiseMps2 = 0.02;     // 1-sigma per axis, m/s^2
constexpr double kHeadingTolDeg = 1.0;       // rms heading error after convergence, deg (offset removed; 0.25 measured, 0.09 before session 18: see docs/ESTIMATORS.md "Magnets the BROAD copy does not hold")
constexpr double kUncorrectedWorseFactor = 3.0;  // without the estimator the rms heading error is at least this many times larger
constexpr double kCoveredShare = 0.95;       // share of scored samples with |heading error| <= 3 sigma

// ENU field: 20 uT north (y), 45 uT down; the offset |b| = 14.9 uT, fixed in the body.
const Eigen::Vector3d kFieldWorldUt(0.0, 20.0, -45.0);
const Eigen::Vector3d kOffsetBodyUt(10.0, -9.0, 6.5);

Eigen::Vector3d body_rate(double t_s) {
  if (t_s < kRestS) {
    return Eigen::Vector3d::Zero();
  }
  const double t = t_s - kRestS;
  return 1.5 * Eigen::Vector3d(std::sin(0.9 * t), std::sin(0.6 * t + 1.0), std::cos(0.4 * t) - 0.3);
}

struct HeadingScore {
  double rms_deg = 0.0;        ///< rms heading error (world z of the rotation-vector error) after kConvergedS
  double covered_share = 0.0;  ///< share of those samples with |error| <= 3 sqrt(published heading variance)
  uint64_t corrected = 0;      ///< samples whose reading had the offset removed
  bool reported = false;       ///< the mag source said "hard_iron_corrected" at least once
};

/// Runs the default filter (field reference configured, hard_iron as given) on the tumbling sensor;
/// the oracle is the simulator's attitude.
HeadingScore run_tumbling(bool hard_iron, bool adaptive_noise = true) {
  ParallelKfParams p;
  p.hard_iron = hard_iron;
  p.mag_adaptive_noise = adaptive_noise;
  p.field_magnitude_ut = kFieldWorldUt.norm();
  p.dip_deg = std::atan2(-kFieldWorldUt.z(), kFieldWorldUt.y()) * kDegPerRad;
  p.imu_delay_s = 0.0;
  ParallelKf kf(p);
  std::mt19937 rng(7);
  std::normal_distribution<double> unit(0.0, 1.0);
  auto noise = [&](double sigma) -> Eigen::Vector3d { return Eigen::Vector3d(unit(rng), unit(rng), unit(rng)) * sigma; };
  const double h = 1.0 / kRateHz;
  const int sub = 20;
  Eigen::Quaterniond q_true(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()));  // heading not at yaw 0
  HeadingScore score;
  double sq = 0.0;
  uint64_t n = 0;
  uint64_t covered = 0;
  const int samples = static_cast<int>(kRunS * kRateHz);
  for (int k = 0; k <= samples; ++k) {
    const double t = k * h;
    if (k > 0) {  // the truth from t - h to t, the rate taken at each sub-step's midpoint
      for (int j = 0; j < sub; ++j) {
        const Eigen::Vector3d w = body_rate(t - h + (j + 0.5) * h / sub);
        const double angle = w.norm() * h / sub;
        if (angle > 0.0) {
          q_true = (q_true * Eigen::Quaterniond(Eigen::AngleAxisd(angle, w.normalized()))).normalized();
        }
      }
    }
    ImuSample s;
    s.stamp_ns = 1'000'000'000 + static_cast<int64_t>(std::llround(t * 1e9));
    s.gyro_rps = body_rate(t) + noise(kGyroNoiseRps);
    s.accel_mps2 = q_true.conjugate() * Eigen::Vector3d(0.0, 0.0, 9.81) + noise(kAccelNoiseMps2);
    s.mag_ut = q_true.conjugate() * kFieldWorldUt + kOffsetBodyUt + noise(kMagNoiseUt);
    s.has_mag = true;
    EXPECT_TRUE(kf.update(s)) << "sample " << k;
    const SourceReports src = kf.sources();
    score.reported = score.reported || src[2].reason == std::string("hard_iron_corrected");
    if (t < kConvergedS) {
      continue;
    }
    const ParallelKfOutput out = kf.output();
    const double err = world_attitude_error(out.q_world_body, q_true).z();
    const double var = kf.attitude_covariance(out)(2, 2);
    sq += err * err;
    covered += std::abs(err) <= 3.0 * std::sqrt(var) ? 1 : 0;
    ++n;
  }
  score.rms_deg = std::sqrt(sq / static_cast<double>(n)) * kDegPerRad;
  score.covered_share = static_cast<double>(covered) / static_cast<double>(n);
  score.corrected = kf.mag_hard_iron_corrected_count();
  return score;
}

TEST(ParallelKfHardIron, GivenATumblingSensorWithABodyFixedOffsetWhenRunWithTheDefaultThenTheHeadingIsWithinToleranceAndCovered) {
  // GIVEN a sensor tumbling for a minute with a 15 uT offset fixed in its body
  // WHEN the default filter (hard_iron on) runs on it
  const HeadingScore on = run_tumbling(true);
  std::printf("hard_iron on: heading rms %.3f deg, %.1f %% within 3 sigma, %llu samples corrected\n", on.rms_deg,
              100.0 * on.covered_share, static_cast<unsigned long long>(on.corrected));
  // THEN the heading after convergence is within tolerance, the published variance covers it, and
  // the magnetometer's source report said that the offset was removed
  EXPECT_LT(on.rms_deg, kHeadingTolDeg);
  EXPECT_GE(on.covered_share, kCoveredShare);
  EXPECT_GT(on.corrected, 0U);
  EXPECT_TRUE(on.reported);
}

TEST(ParallelKfHardIron, GivenATumblingSensorWithABodyFixedOffsetWhenHardIronIsOffThenTheHeadingIsWorse) {
  // GIVEN the same sensor, WHEN the filter runs with hard_iron: false (and without
  // mag_adaptive_noise, which weighs an uncorrected offset's field as a disturbance and so resists
  // it too, 2.48 deg here: the control isolates what the estimator does)
  const HeadingScore on = run_tumbling(true);
  const HeadingScore off = run_tumbling(false, false);
  std::printf("hard_iron off: heading rms %.3f deg (on: %.3f deg; off with mag_adaptive_noise %.3f deg)\n", off.rms_deg,
              on.rms_deg, run_tumbling(false).rms_deg);
  // THEN nothing is corrected and the heading is clearly worse than with the estimator
  EXPECT_EQ(off.corrected, 0U);
  EXPECT_FALSE(off.reported);
  EXPECT_GT(off.rms_deg, kUncorrectedWorseFactor * on.rms_deg);
}

// Issue 32: a magnet attached to a hand-held sensor at rest and removed during the motion (BROAD's
// protocol, trials 32/34/36), with offsets the BROAD copy does not hold. The oracle is the
// simulator's attitude. Times in s, offsets in uT.
// (the run: poise/testing/attached_magnet.h)
constexpr double kMagnetHeadingTolDeg = 3.0;  // rms heading error over the motion, deg (0.1-1.1 measured)
constexpr double kZ95 = 1.96;                 // the 95 % bound of a normal heading error, in sigmas

struct MagnetRun {
  double heading_rms_deg = 0.0;  ///< over the motion
  double covered = 0.0;          ///< share of the motion's samples with |heading error| <= 1.96 sigma
};

/// Rms heading error (world z of the rotation-vector error), deg, over the motion of a hand-held
/// run of `cfg` (testing::attached_magnet_hand_held*: kept near level, the rotation shows the
/// offset's vertical part slowly; the offset fixed in the body from kMagnetOnS to kMagnetOffS, +
/// ramps) with the filter `p`; and the share of those samples the published heading variance covers
/// at 95 %.
MagnetRun magnet_run(const sim::SimConfig& cfg, const ParallelKfParams& p, double score_from_s = 0.0,
                     uint64_t* reference_moves = nullptr) {
  ParallelKf kf(p);
  sim::SensorSimulator sim(cfg);
  double sq = 0.0;
  uint64_t n = 0;
  uint64_t covered = 0;
  while (!sim.done()) {
    const sim::SimSample s = sim.next();
    kf.update(s.imu);
    if (!kf.initialized() || !s.truth.moving || s.truth.t_s < score_from_s) {
      continue;
    }
    const ParallelKfOutput out = kf.output();
    const double err = world_attitude_error(out.q_world_body, s.truth.q_world_body).z();
    const double var = kf.attitude_covariance(out)(2, 2);
    sq += err * err;
    covered += std::abs(err) <= kZ95 * std::sqrt(var) ? 1 : 0;
    ++n;
  }
  if (reference_moves != nullptr) {
    *reference_moves = kf.field_offset_moves_count();
  }
  MagnetRun r;
  r.heading_rms_deg = n > 0 ? std::sqrt(sq / static_cast<double>(n)) * kDegPerRad : 1e9;
  r.covered = n > 0 ? static_cast<double>(covered) / static_cast<double>(n) : 0.0;
  return r;
}

/// The default filter told the simulated sensor's figures, as config/hosts/simulated.yaml tells them.
ParallelKfParams told_params(const sim::SimConfig& cfg) {
  ParallelKfParams p;
  p.imu_delay_s = 0.0;
  p.gyro_bias_walk_rps_per_sqrt_s = 0.0;
  p.gyro_noise_density_rps_per_sqrt_hz = cfg.noise.sigma_gyro_rps / std::sqrt(cfg.rate_hz);
  p.gyro_scale_error = 0.0;
  return p;
}

/// magnet_run() of testing::attached_magnet_hand_held, the simulated sensor's figures told.
MagnetRun attached_magnet_run(const Eigen::Vector3d& offset_ut) {
  const sim::SimConfig cfg = testing::attached_magnet_hand_held(offset_ut);
  return magnet_run(cfg, told_params(cfg));
}

// Session 27: a magnet on the sensor from power-on, the field reference learnt at start-up (the
// default: nothing configured), so the reference holds the offset (before: gated until reacquired
// after 20 s, then KF2 slowly away from the start's heading; 0.56 / 25.96 / 12.54 deg rms, 67 %
// inside for the two larger turns; now 0.21-0.22 deg, 100 %). The sensor tumbles (the offset
// shows along every axis within seconds); scored from kPowerOnScoreFromS (the offset cannot be
// told from the Earth's field before the rotation has shown it). Times in s.
constexpr double kPowerOnScoreFromS = testing::kMagnetRestS + 10.0;
// rms heading error from then on, deg: 2 sigma of the heading one reading gives, which the heading
// restarts on (the simulator's 0.2 uT per axis across the 15 uT horizontal field: 0.76 deg)
constexpr double kPowerOnHeadingTolDeg = 1.5;

TEST(ParallelKfHardIron, GivenAMagnetOnTheSensorAtPowerOnWhenTheReferenceIsLearntThenTheOffsetIsTakenOutOfItAndTheHeadingHolds) {
  for (const Eigen::Vector3d& offset : {Eigen::Vector3d(0.0, -10.0, 0.0), Eigen::Vector3d(12.0, 0.0, 5.0),
                                        Eigen::Vector3d(-8.0, 6.0, -6.0)}) {
    // GIVEN a tumbling sensor in BROAD's field with a magnet fixed to it from the first sample to the end
    sim::SimConfig cfg = testing::attached_magnet_tumbling(offset);
    cfg.magnets[0].start_s = 0.0;
    cfg.magnets[0].ramp_s = 0.0;
    cfg.magnets[0].hold_s = cfg.duration_s;
    // WHEN the default filter (the simulated sensor's figures told, no field reference) runs on it
    uint64_t moves = 0;
    const MagnetRun r = magnet_run(cfg, told_params(cfg), kPowerOnScoreFromS, &moves);
    std::printf("%.0f uT along (%.0f, %.0f, %.0f) from power-on: heading rms %.2f deg from %.0f s, "
                "%.1f %% inside the 95 %% bound, %llu reference moves\n",
                offset.norm(), offset.x(), offset.y(), offset.z(), r.heading_rms_deg, kPowerOnScoreFromS,
                100.0 * r.covered, static_cast<unsigned long long>(moves));
    // THEN the start-up's reference is moved once to the field without the offset (the heading
    // restarts on it), and the heading holds
    EXPECT_EQ(moves, 1U);
    EXPECT_LT(r.heading_rms_deg, kPowerOnHeadingTolDeg);
  }
}

TEST(ParallelKfHardIron, GivenAMagnetPutOnInTheMotionAfterTheEstimateSawNoneThenTheStartUpsReferenceIsKept) {
  // GIVEN the tumbling sensor without a magnet until 30 s into the motion (the hard-iron estimate
  // converges on no offset first), then with one put on in 0.2 s (the field there fits the
  // reference without the offset as well: without the estimate's evidence the reference was moved,
  // 9.35 deg rms over the motion; with it 3.82)
  const Eigen::Vector3d offset(12.0, 0.0, 5.0);
  sim::SimConfig cfg = testing::attached_magnet_tumbling(offset);
  cfg.magnets[0].start_s = testing::kMagnetRestS + 30.0;
  cfg.magnets[0].ramp_s = 0.2;
  cfg.magnets[0].hold_s = cfg.duration_s;
  // WHEN the default filter runs on it
  uint64_t moves = 0;
  const MagnetRun r = magnet_run(cfg, told_params(cfg), 0.0, &moves);
  std::printf("13 uT put on in the motion: heading rms over the motion %.2f deg, %llu reference moves\n",
              r.heading_rms_deg, static_cast<unsigned long long>(moves));
  // THEN the reference learnt at start-up (the Earth's) is not moved when the offset is removed
  // (the heading over the motion is not this test's: a magnet put on in the motion turns it until
  // the estimate removes the offset, docs/ESTIMATORS.md "Magnets the BROAD copy does not hold")
  EXPECT_EQ(moves, 0U);
}

TEST(ParallelKfHardIron, GivenAMagnetAttachedAtRestAndRemovedInMotionWhenItsOffsetIsOneTheGateCannotTellThenTheHeadingHolds) {
  // GIVEN a hand-held sensor in BROAD's field (44 uT, horizontal 15 uT), a magnet attached at rest
  // and removed during the motion, its body offset
  //   - 25 uT along -y (against the horizontal field at the start): where it reverses the
  //     horizontal field the sum passes both the norm and the dip gate (42.5 uT, 76 deg);
  //   - 25 uT along -x (across it): passes the gate at other orientations;
  //   - 60 uT along +x: gated throughout, so after mag_max_reject_s (60 s) used anyway.
  // Before: 108.7 / 24.0 / 13.2 deg rms; the hard-iron estimate in this motion converges late or
  // not at all (the vertical part of the offset shows slowly when the sensor is kept near level).
  const struct {
    Eigen::Vector3d offset;
    const char* what;
  } cases[] = {{{0.0, -25.0, 0.0}, "25 uT along -y"}, {{-25.0, 0.0, 0.0}, "25 uT along -x"},
               {{60.0, 0.0, 0.0}, "60 uT along +x"}};
  for (const auto& c : cases) {
    // WHEN the default filter runs on it
    const double rms = attached_magnet_run(c.offset).heading_rms_deg;
    std::printf("%s: heading rms over the motion %.2f deg\n", c.what, rms);
    // THEN the heading stays within tolerance of the truth: the raw field is not used while the
    // offset cannot be removed (nor when it moved at rest), and the offset is dropped once gone
    EXPECT_LT(rms, kMagnetHeadingTolDeg) << c.what;
  }
}

// A small magnet (3-10 uT: below min_applied_ut, or not significant against the estimate's
// covariance for long) attached at rest, then the hand-held motion. The field moved at rest; in the
// motion the raw field carries the offset and passes the gate (10 uT across 15 uT horizontal turns
// the heading 34 deg, |m| by 1.1 uT). Session 20 (issue 32).
constexpr double kSmallMagnetHeadingTolDeg = 2.0;  // rms heading error over the motion, deg (main 3.8-20)
/// least share of the motion's samples inside the published 95 % heading bound (the band
/// starts at 85 %)
constexpr double kSmallMagnetMinCovered = 0.85;

TEST(ParallelKfHardIron, GivenASmallMagnetAttachedAtRestWhenTheSensorIsThenHandHeldThenTheHeadingHoldsAndIsCovered) {
  // GIVEN a hand-held sensor in BROAD's field (44 uT, horizontal 15 uT) and a small magnet attached
  // at rest, removed during the motion, its body offset
  //   - 3 uT along -x, 5 uT along (-1, 1, -1)/sqrt 3, 10 uT along -y;
  //   - 8 uT along +x (across the horizontal field at the start): at rest the field pulls the
  //     heading 0.5 deg before the rest detector's low-pass sees it move; that turn is taken back
  //     when it does (field_moved_at_rest; session 20 without it: 1.24 deg, 2 % inside).
  // Before (main at 782f3ea): 8.23 / 3.80 / 6.96 / 19.97 deg rms, 38 / 93 / 93 / 31 % inside.
  const double r3 = 1.0 / std::sqrt(3.0);
  const struct {
    Eigen::Vector3d offset;
    const char* what;
  } cases[] = {{{-3.0, 0.0, 0.0}, "3 uT along -x"},
               {{-5.0 * r3, 5.0 * r3, -5.0 * r3}, "5 uT along (-1, 1, -1)"},
               {{0.0, -10.0, 0.0}, "10 uT along -y"},
               {{8.0, 0.0, 0.0}, "8 uT along +x"}};
  for (const auto& c : cases) {
    // WHEN the default filter runs on it
    const MagnetRun r = attached_magnet_run(c.offset);
    std::printf("%s: heading rms over the motion %.2f deg, %.1f %% inside the 95 %% bound\n", c.what,
                r.heading_rms_deg, 100.0 * r.covered);
    // THEN the heading stays within tolerance of the truth (the field that moved at rest is held
    // refused in the motion until the hard-iron estimate has judged it, or it is back at the
    // rest's field) and the published heading variance covers the error
    EXPECT_LT(r.heading_rms_deg, kSmallMagnetHeadingTolDeg) << c.what;
    EXPECT_GE(r.covered, kSmallMagnetMinCovered) << c.what;
  }
}

// At rest the body does not turn: the heading turn KF2's fields give while a magnet's field ramps
// in across the horizontal field, before the rest detector's low-pass sees it move, is taken back
// when it does (session 21, issue 32).
/// Heading change kept over the attachment at rest, deg: what KF2 turns before the reading leaves
/// the gate's norm tolerance of the rest's field (2.2 uT across the 15 uT horizontal field turns its
/// direction 8.3 deg; the 8 uT ramp over 1.5 s gets there in 0.41 s, which KF2's lag of about 10 s
/// follows by about 20 deg/s x 0.41^2 s^2 / (2 x 10 s) = 0.17 deg), and the heading's noise at rest.
constexpr double kRestTurnKeptTolDeg = 0.25;
TEST(ParallelKfHardIron, GivenAMagnetAttachedAtRestAcrossTheFieldWhenTheMoveIsSeenThenTheHeadingTurnItGaveIsTakenBack) {
  // GIVEN the session-20 run's 8 uT along +x (across the horizontal field), the simulated
  // sensor's figures told
  const sim::SimConfig cfg = testing::attached_magnet_hand_held(Eigen::Vector3d(8.0, 0.0, 0.0));
  ParallelKf kf(told_params(cfg));
  sim::SensorSimulator sim(cfg);
  // WHEN it runs through the attachment (the ramp from kMagnetOnS) to the end of the rest
  double before = std::nan("");
  double after = std::nan("");
  double largest_pull = 0.0;
  while (!sim.done()) {
    const sim::SimSample s = sim.next();
    kf.update(s.imu);
    if (!kf.initialized()) {
      continue;
    }
    const double err = world_attitude_error(kf.q_world_body(), s.truth.q_world_body).z() * kDegPerRad;
    if (s.truth.t_s < testing::kMagnetOnS) {
      before = err;
    } else if (s.truth.t_s < testing::kMagnetRestS - 0.5) {
      largest_pull = std::max(largest_pull, std::abs(err - before));
      after = err;
    } else {
      break;
    }
  }
  std::printf("heading error before %.3f deg, at the end of the rest %.3f deg (largest change %.3f deg), turns "
              "taken back %llu\n",
              before, after, largest_pull, static_cast<unsigned long long>(kf.rest_turns_reverted_count()));
  // THEN the field was found moved once and the heading is back within tolerance of where it was
  // (the pull it had reached is larger: the turn was there and was taken back)
  EXPECT_EQ(kf.rest_turns_reverted_count(), 1u);
  EXPECT_LT(std::abs(after - before), kRestTurnKeptTolDeg);
  EXPECT_GT(largest_pull, kRestTurnKeptTolDeg);
}

// The same magnet as BROAD's sensor sees it (its noise, the filter's defaults). While the removed
// offset is still being learnt its error, of the estimate's covariance, is in every corrected
// reading: KF2 takes it as part of the reading's noise (session 21, issue 32).
TEST(ParallelKfHardIron, GivenAnAppliedOffsetStillUncertainWhenHandHeldWithBroadsNoiseThenTheHeadingHoldsAndIsCovered) {
  // GIVEN a hand-held sensor with BROAD's noise and a magnet attached at rest, removed in the
  // motion: 8-10 uT, along the body axes that turn the horizontal field most in this motion
  const struct {
    Eigen::Vector3d offset;
    uint64_t seed;
    const char* what;
  } cases[] = {{{0.0, 8.0, 0.0}, 2, "8 uT along +y"},
               {{10.0, 0.0, 0.0}, 2, "10 uT along +x"},
               {{0.0, 10.0, 0.0}, 2, "10 uT along +y"}};
  for (const auto& c : cases) {
    // WHEN the default filter runs on it, the sensor's figures not told
    const sim::SimConfig cfg = testing::attached_magnet_hand_held_broad_noise(c.offset, c.seed);
    ParallelKfParams p;
    p.imu_delay_s = 0.0;
    const MagnetRun r = magnet_run(cfg, p);
    std::printf("%s: heading rms over the motion %.2f deg, %.1f %% inside the 95 %% bound\n", c.what,
                r.heading_rms_deg, 100.0 * r.covered);
    // THEN the heading stays within tolerance of the truth and the published variance covers it
    EXPECT_LT(r.heading_rms_deg, kSmallMagnetHeadingTolDeg) << c.what;
    EXPECT_GE(r.covered, kSmallMagnetMinCovered) << c.what;
  }
}

// A magnet put on while the sensor is carried without turning (a translation, BROAD's "slow
// translation" kind of motion): no rotation shows a body-fixed offset to the comparisons, but the
// step does, in the gyro frame, between two readings (HardIronStep::kStep, session 26; opt-in:
// hard_iron_estimator.step_detection). Before it,
// the raw field carried the offset into the heading: 10 uT across the 15 uT horizontal field turns
// it up to 34 deg, and the gate passes it at many orientations.
/// rms heading error over the motion, deg: what the step's estimate leaves, its error per axis
/// sqrt(var_j + (var_k + var_k2) / 4) with the simulator's 0.2 uT reading noise, 0.24 uT, across
/// the 15 uT horizontal field is 0.9 deg; three times that
constexpr double kCarriedMagnetHeadingTolDeg = 2.7;
constexpr double kCarriedMagnetRampS = 0.2;  ///< the magnet put on by hand, s

TEST(ParallelKfHardIron, GivenAMagnetPutOnWhileTheSensorIsCarriedWithoutTurningThenItsStepIsRemovedAndTheHeadingHolds) {
  // GIVEN a sensor at rest, then carried about without turning (translation only, 80 s), a magnet
  // put on 20 s into the motion (not at a multiple of the estimator's 0.25 s grid) and left on
  const struct {
    Eigen::Vector3d offset;
    const char* what;
  } cases[] = {{{10.0, 0.0, 0.0}, "10 uT along +x"},
               {{0.0, -10.0, 0.0}, "10 uT along -y"},
               {{-8.0, 6.0, 5.0}, "11 uT along (-8, 6, 5)"},
               {{20.0, 20.0, -10.0}, "30 uT along (2, 2, -1)"}};
  for (const auto& c : cases) {
    sim::SimConfig cfg = testing::attached_magnet_hand_held(c.offset);
    sim::MotionSegment& motion = cfg.segments[1];
    motion.name = "carried";
    motion.rotation_amplitude_rps = 0.0;
    motion.level_gain_per_s = 0.0;
    cfg.magnets[0].start_s = testing::kMagnetRestS + 20.07;
    cfg.magnets[0].ramp_s = kCarriedMagnetRampS;
    cfg.magnets[0].hold_s = cfg.duration_s;
    // WHEN the default filter, told the simulated sensor's figures, runs on it with the offset's
    // steps taken (hard_iron_estimator.step_detection; without them: 18.6 / 0.10 / 10.6 / 15.4 deg)
    ParallelKfParams p = told_params(cfg);
    p.hard_iron_estimator.step_detection = true;
    const MagnetRun r = magnet_run(cfg, p);
    std::printf("%s: heading rms over the motion %.2f deg, %.1f %% inside the 95 %% bound\n", c.what,
                r.heading_rms_deg, 100.0 * r.covered);
    // THEN the heading stays within what the step's estimate leaves, and the published variance
    // covers it
    EXPECT_LT(r.heading_rms_deg, kCarriedMagnetHeadingTolDeg) << c.what;
    EXPECT_GE(r.covered, kSmallMagnetMinCovered) << c.what;
  }
}

TEST(ParallelKfHardIron, GivenTheHardIronKeysInYamlWhenLoadedThenTheyAreReadAndHostileValuesAreRefusedByName) {
  const std::string path = ::testing::TempDir() + "/pkf_hard_iron.yaml";
  auto write = [&](const std::string& text) {
    std::FILE* f = std::fopen(path.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs(text.c_str(), f);
    std::fclose(f);
  };
  // the defaults: on; the paper configuration: off
  EXPECT_TRUE(ParallelKfParams::defaults().hard_iron);
  EXPECT_FALSE(ParallelKfParams::paper().hard_iron);
  const std::string dir = std::string(POISE_SOURCE_DIR) + "/config/filters/";
  EXPECT_FALSE(load_parallel_kf_params(dir + "parallel_kf_paper.yaml").hard_iron);
  EXPECT_TRUE(load_parallel_kf_params(dir + "parallel_kf.yaml").hard_iron);
  write("parallel_kf:\n  hard_iron: false\n  hard_iron_estimator:\n    min_applied_ut: 8\n    noise_ut: 2\n"
        "    consistency_tau_s: 0\n    removed_log_lr: 0\n    removed_tau_s: 2\n    step_detection: true\n");
  const ParallelKfParams p = load_parallel_kf_params(path);
  EXPECT_FALSE(ParallelKfParams::defaults().hard_iron_estimator.step_detection);  // opt-in
  EXPECT_TRUE(p.hard_iron_estimator.step_detection);
  EXPECT_FALSE(p.hard_iron);
  EXPECT_EQ(p.hard_iron_estimator.min_applied_ut, 8.0);
  EXPECT_EQ(p.hard_iron_estimator.noise_ut, 2.0);
  EXPECT_EQ(p.hard_iron_estimator.consistency_tau_s, 0.0);
  EXPECT_EQ(p.hard_iron_estimator.removed_log_lr, 0.0);
  EXPECT_EQ(p.hard_iron_estimator.removed_tau_s, 2.0);
  // hostile values: each refused with a message naming the key
  const struct {
    const char* yaml;
    const char* key;
  } bad[] = {
      {"  hard_iron: maybe\n", "hard_iron"},
      {"  hard_iron: 3\n", "hard_iron"},
      {"  hard_iron_estimator:\n    min_applied_ut: -1\n", "min_applied_ut"},
      {"  hard_iron_estimator:\n    noise_ut: .nan\n", "noise_ut"},
      {"  hard_iron_estimator:\n    lag_s: 1e308\n", "lag_s"},
      {"  hard_iron_estimator:\n    lag_s: 1e-12\n", "lag_s"},
      {"  hard_iron_estimator:\n    prior_sigma_ut: 1e308\n", "prior_sigma_ut"},
      {"  hard_iron_estimator:\n    noise_ut: 1e308\n", "noise_ut"},
      {"  hard_iron_estimator:\n    converged_sigma_ut: 0\n", "converged_sigma_ut"},
      {"  hard_iron_estimator:\n    min_rotation_rad: 4\n", "min_rotation_rad"},
      {"  hard_iron_estimator:\n    gate_chi2: -.inf\n", "gate_chi2"},
      {"  hard_iron_estimator:\n    consistency_tau_s: -5\n", "consistency_tau_s"},
      {"  hard_iron_estimator:\n    consistency_tau_s: .nan\n", "consistency_tau_s"},
      {"  hard_iron_estimator:\n    removed_log_lr: -1\n", "removed_log_lr"},
      {"  hard_iron_estimator:\n    removed_log_lr: .inf\n", "removed_log_lr"},
      {"  hard_iron_estimator:\n    removed_tau_s: 0\n", "removed_tau_s"},
      {"  hard_iron_estimator:\n    removed_tau_s: .nan\n", "removed_tau_s"},
      {"  hard_iron_estimator:\n    noise_tau_s: -1\n", "noise_tau_s"},
      {"  hard_iron_estimator:\n    noise_tau_s: 1e308\n", "noise_tau_s"},
      {"  hard_iron_estimator:\n    noise_tau_s: .nan\n", "noise_tau_s"},
      {"  hard_iron_estimator:\n    no_such_key: 1\n", "no_such_key"},
      {"  hard_iron_estimator:\n    prior_sigma_ut: [1, 2]\n", "prior_sigma_ut"},
      {"  hard_iron_estimator:\n    step_detection: maybe\n", "step_detection"},
      {"  hard_iron_estimator:\n    step_detection: 1e308\n", "step_detection"},
      {"  hard_iron_estimator:\n    step_detection: [true]\n", "step_detection"},
      {"  hard_iron_estimator:\n    step_detection: true\n    step_detection: false\n", "step_detection"},
  };
  for (const auto& b : bad) {
    write(std::string("parallel_kf:\n") + b.yaml);
    const std::string msg = testing::error_message([&] { load_parallel_kf_params(path); });
    EXPECT_NE(msg.find(b.key), std::string::npos) << b.yaml << " -> '" << msg << "'";
  }
  // the struct path names the section and the key
  ParallelKfParams q;
  q.hard_iron_estimator.reset_after_s = -2.0;
  const std::string msg = testing::invalid_argument_message([&] { q.validate(); });
  EXPECT_NE(msg.find("parallel_kf hard_iron_estimator parameter reset_after_s must be"), std::string::npos) << msg;
}

}  // namespace
}  // namespace poise
