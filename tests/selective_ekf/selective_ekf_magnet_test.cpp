// The selective EKF (IMU only, kSplit) next to a magnet attached to the sensor (issues 31 and 32,
// BROAD's "attached magnet" trials): the simulator's hand-held run in BROAD's field with a
// body-fixed offset attached at rest and removed in the motion, and the `hard_iron` YAML keys.
// Oracles: the simulator's truth (the heading error) and the published covariance's heading
// variance (the share of samples its 95 % bound covers).
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/sim/sensor_simulator.h"

#include "poise/testing/attached_magnet.h"
#include "poise/testing/param_errors.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>

namespace poise {
namespace {

constexpr double kHeadingTolDeg = 3.0;  // rms heading error over the motion, deg (the parallel KF's test's)
/// rms heading error over the motion with a small offset left in (not removed: a bound on the
/// error, not an accuracy claim; the offset turns the heading by up to atan(5 / 15), 18 deg), deg
constexpr double kSmallOffsetHeadingTolDeg = 8.0;
constexpr double kZ95 = 1.96;           // the 95 % bound of a normal heading error, in sigmas
/// Least share of the motion's samples whose heading error the published 95 % bound covers (the
/// issue's band starts at 85 %)
constexpr double kMinCovered = 0.85;

struct MagnetRun {
  double heading_rms_deg = 0.0;  ///< over the motion
  double covered = 0.0;          ///< share of the motion's samples with |heading error| <= 1.96 sigma
  uint64_t reference_moves = 0;  ///< the gate's start-up reference moved by the offset (FieldGate::offset_removed)
};

/// A run of poise/testing/attached_magnet.h; the filter told the simulated sensor's figures
/// (`told`), or its defaults (BROAD's sensor's figures); scored from `score_from_s` into the run.
MagnetRun attached_magnet_run(const sim::SimConfig& cfg, bool told = true, double score_from_s = 0.0) {
  SelectiveEkfParams p;  // the simulated sensor's figures, as config/filters/selective_ekf_sim.yaml
  p.imu_delay_s = 0.0;
  if (told) {
    p.gyro_noise_density_rps_per_sqrt_hz = cfg.noise.sigma_gyro_rps / std::sqrt(cfg.rate_hz);
    p.accel_noise_density_mps2_per_sqrt_hz = cfg.noise.sigma_accel_mps2 / std::sqrt(cfg.rate_hz);
    p.gyro_bias_walk_rps_per_sqrt_s = 0.0;
  }
  SelectiveEkf ekf(p);
  sim::SensorSimulator sim(cfg);
  double sq = 0.0;
  uint64_t n = 0;
  uint64_t covered = 0;
  while (!sim.done()) {
    const sim::SimSample s = sim.next();
    ekf.update_imu(s.imu);
    if (!ekf.initialized() || !s.truth.moving || s.truth.t_s < score_from_s) {
      continue;
    }
    const double err = world_attitude_error(ekf.q_world_body(), s.truth.q_world_body).z();
    const double var = ekf.attitude_covariance()(2, 2);
    sq += err * err;
    covered += std::abs(err) <= kZ95 * std::sqrt(var) ? 1 : 0;
    ++n;
  }
  MagnetRun r;
  r.heading_rms_deg = n > 0 ? std::sqrt(sq / static_cast<double>(n)) * kDegPerRad : 1e9;
  r.covered = n > 0 ? static_cast<double>(covered) / static_cast<double>(n) : 0.0;
  r.reference_moves = ekf.state().field_gate.offset_moves;
  return r;
}

/// One magnet of a test's cases: its body offset, uT, and how the output names it.
struct MagnetCase {
  Eigen::Vector3d offset;
  const char* what;
};

/// attached_magnet_run with its figures printed under the case's name.
MagnetRun reported_run(const sim::SimConfig& cfg, const MagnetCase& c, bool told = true) {
  const MagnetRun r = attached_magnet_run(cfg, told);
  std::printf("%s: heading rms over the motion %.2f deg, %.1f %% inside the 95 %% bound\n", c.what, r.heading_rms_deg,
              100.0 * r.covered);
  return r;
}

TEST(SelectiveEkfMagnet, GivenAMagnetAttachedAtRestAndRemovedInMotionWhenTheGateCannotTellThenTheHeadingHoldsAndIsCovered) {
  // GIVEN a hand-held sensor in BROAD's field, a magnet attached at rest and removed in the motion,
  // its body offset
  //   - 25 uT along -y (against the horizontal field at the start): where it reverses the
  //     horizontal field the sum passes both the norm and the dip gate;
  //   - 25 uT along -x (across it): passes the gate at other orientations;
  //   - 10 uT along +x (across it, at rest: |m| moves by 1.1 uT of 44, the heading by 34 deg).
  // Before (no hard-iron estimate, no moved-at-rest test): 120.4 / 17.5 / 21.7 deg rms, 0 / 24 /
  // 0 % covered.
  const MagnetCase cases[] = {{{0.0, -25.0, 0.0}, "25 uT along -y"},
               {{-25.0, 0.0, 0.0}, "25 uT along -x"},
               {{10.0, 0.0, 0.0}, "10 uT along +x"}};
  for (const auto& c : cases) {
    // WHEN the default filter (IMU only) runs on it
    const MagnetRun r = reported_run(testing::attached_magnet_hand_held(c.offset), c);
    // THEN the heading stays within tolerance of the truth (the raw field is not used while the
    // offset cannot be removed, nor when it moved at rest) and the published heading variance
    // covers its error
    EXPECT_LT(r.heading_rms_deg, kHeadingTolDeg) << c.what;
    EXPECT_GE(r.covered, kMinCovered) << c.what;
  }
}

TEST(SelectiveEkfMagnet, GivenASmallMagnetTheEstimateDoesNotRemoveWhenTumblingThenThePublishedHeadingVarianceCoversItsError) {
  // GIVEN a tumbling sensor in BROAD's field with a small magnet attached at rest and removed in
  // the motion: 3 uT along +x and along (1, -1, -1) / sqrt(3), 5 uT along +x. The hard-iron
  // estimate converges on it but does not remove it (|b| at or below min_applied_ut, 5 uT), so
  // the heading row fuses the raw field and the heading carries the offset's error (2-6 deg).
  // Before (no "offset" term: the published variance left it out): 72.3 / 19.6 / 62.5 % covered (heading rms 2.63 / 6.10 / 3.94 deg).
  const MagnetCase cases[] = {{{3.0, 0.0, 0.0}, "3 uT along +x"},
               {Eigen::Vector3d(1.0, -1.0, -1.0).normalized() * 3.0, "3 uT along (1, -1, -1)"},
               {{5.0, 0.0, 0.0}, "5 uT along +x"}};
  for (const auto& c : cases) {
    // WHEN the default filter (IMU only) runs on it
    const MagnetRun r = reported_run(testing::attached_magnet_tumbling(c.offset), c);
    // THEN the published heading variance covers the error the unremoved offset puts in (the
    // heading row's response to it through its own gains, SelectiveEkfState::heading_per_offset)
    EXPECT_GE(r.covered, kMinCovered) << c.what;
    EXPECT_LT(r.heading_rms_deg, kSmallOffsetHeadingTolDeg) << c.what;
  }
}

TEST(SelectiveEkfMagnet, GivenAMagnetRemovedInMotionWhenTheHardIronEstimateReopensThenTheHeadingErrorItLeftStaysCovered) {
  // GIVEN a hand-held sensor with BROAD's noise, a magnet attached at rest and removed in the
  // motion (10 and 15 uT along -y, seed 1: the estimate removes it, then reopens some seconds after
  // the removal). What the offset put into the heading before the estimate reopened stays until
  // the rows correct it away (SelectiveEkfState::offset_left_var). Before (the terms dropped at
  // the reopen): 79.2 / 77.7 % covered, heading rms 3.66 / 1.94 deg (the scratch sweep's cells).
  const MagnetCase cases[] = {{{0.0, -10.0, 0.0}, "10 uT along -y"}, {{0.0, -15.0, 0.0}, "15 uT along -y"}};
  for (const auto& c : cases) {
    // WHEN the default filter (IMU only, BROAD's sensor's figures) runs on it
    const MagnetRun r = reported_run(testing::attached_magnet_hand_held_broad_noise(c.offset, 1), c, false);
    // THEN the published heading variance covers the heading error (the accuracy is a bound only:
    // this change is to the covariance)
    EXPECT_GE(r.covered, kMinCovered) << c.what;
    EXPECT_LT(r.heading_rms_deg, kSmallOffsetHeadingTolDeg) << c.what;
  }
}

// Session 27: a magnet on the tumbling sensor from power-on, the field reference learnt at start-up
// on the field plus the offset (the parallel KF's test of the same name: the gate is shared). Scored
// from 10 s into the motion (the offset cannot be told from the Earth's field before the rotation
// has shown it). Before: 0.17 / 21.62 / 11.14 deg rms, 100 / 27.9 / 38.0 % inside (the gate
// reacquired the field after 20 s and the heading came back slowly); now 0.26-0.29 deg, 100 %.
constexpr double kPowerOnScoreFromS = testing::kMagnetRestS + 10.0;  // s

TEST(SelectiveEkfMagnet, GivenAMagnetOnTheSensorAtPowerOnWhenTheReferenceIsLearntThenTheOffsetIsTakenOutOfItAndTheHeadingHolds) {
  for (const MagnetCase& c : {MagnetCase{Eigen::Vector3d(0.0, -10.0, 0.0), "10 uT along -y from power-on"},
                              MagnetCase{Eigen::Vector3d(12.0, 0.0, 5.0), "13 uT along (12, 0, 5) from power-on"},
                              MagnetCase{Eigen::Vector3d(-8.0, 6.0, -6.0), "12 uT along (-8, 6, -6) from power-on"}}) {
    // GIVEN a tumbling sensor with the magnet fixed to it from the first sample to the end
    sim::SimConfig cfg = testing::attached_magnet_tumbling(c.offset);
    cfg.magnets[0].start_s = 0.0;
    cfg.magnets[0].ramp_s = 0.0;
    cfg.magnets[0].hold_s = cfg.duration_s;
    // WHEN the filter (no field reference configured) runs on it
    const MagnetRun r = attached_magnet_run(cfg, true, kPowerOnScoreFromS);
    std::printf("%s: heading rms from %.0f s %.2f deg, %.1f %% inside the 95 %% bound, %llu reference moves\n", c.what,
                kPowerOnScoreFromS, r.heading_rms_deg, 100.0 * r.covered,
                static_cast<unsigned long long>(r.reference_moves));
    // THEN the start-up's reference is moved once to the field without the offset, and the heading
    // holds and is covered
    EXPECT_EQ(r.reference_moves, 1U) << c.what;
    EXPECT_LT(r.heading_rms_deg, kHeadingTolDeg) << c.what;
    EXPECT_GE(r.covered, kMinCovered) << c.what;
  }
}

TEST(SelectiveEkfMagnet, GivenTheHardIronKeysInYamlWhenLoadedThenTheyAreReadAndHostileValuesAreRefusedByName) {
  const std::string path = ::testing::TempDir() + "/sel_hard_iron.yaml";
  auto write = [&](const std::string& text) {
    std::FILE* f = std::fopen(path.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs(text.c_str(), f);
    std::fclose(f);
  };
  EXPECT_TRUE(SelectiveEkfParams{}.hard_iron);
  write("selective_ekf:\n  hard_iron: false\n  hard_iron_estimator:\n    min_applied_ut: 8\n    removed_log_lr: 0\n");
  const SelectiveEkfParams p = load_selective_ekf_params(path);
  EXPECT_FALSE(p.hard_iron);
  EXPECT_EQ(p.hard_iron_estimator.min_applied_ut, 8.0);
  EXPECT_EQ(p.hard_iron_estimator.removed_log_lr, 0.0);
  // hostile values and unknown keys: refused with a message naming the key
  write("selective_ekf:\n  hard_iron_estimator:\n    lag_s: -1\n");
  EXPECT_NE(testing::error_message([&] { load_selective_ekf_params(path); }).find("lag_s"), std::string::npos);
  write("selective_ekf:\n  hard_iron_estimator:\n    no_such_key: 1\n");
  EXPECT_NE(testing::error_message([&] { load_selective_ekf_params(path); }).find("no_such_key"), std::string::npos);
}

}  // namespace
}  // namespace poise
