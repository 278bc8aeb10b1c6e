// The parallel KF's heading in a field whose horizontal direction turns where the sensor goes
// (issue 32, BROAD trial 30: a magnet fixed in the room; the field keeps its norm and dip, so the
// gate accepts it). Oracle: the simulator's truth (the undisturbed field's north).
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/sim/sensor_simulator.h"
#include "poise/testing/rotated_field.h"
#include "told_sensor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

namespace poise {
namespace {

constexpr double kRateHz = 200.0;            // Hz
constexpr double kRotationDeg = 10.0;        // the field's horizontal rotation, amplitude, deg
constexpr double kRotationPeriodS = 20.0;    // its period, s
constexpr double kRotationStartS = 20.0;     // it begins (the reference learnt and settled), s
constexpr double kScoredFromS = 40.0;        // heading error scored from (a period after the start), s
constexpr double kScoredToS = 140.0;         // ... to, s
constexpr int kRuns = 2;                     // seeds
constexpr double kZ95 = 1.96;                // the 95 % bound of a normal heading error, in sigmas

/// The filter told the simulated sensor (told_the_simulated_sensor), mag_adaptive_noise as given.
ParallelKfParams told(const sim::SimConfig& cfg, bool adaptive) {
  ParallelKfParams p = told_the_simulated_sensor(cfg);
  p.mag_adaptive_noise = adaptive;
  return p;
}

struct HeadingFigures {
  double rms_deg = 0.0;        ///< the heading error's RMS over the scored time, deg
  double rotation_rms_deg = 0.0;  ///< the field rotation's RMS over the same time, deg
  double covered = 0.0;        ///< share of the scored samples with |heading error| <= 1.96 published sigma
};

HeadingFigures run(uint64_t seed, bool adaptive, double amplitude_deg = kRotationDeg) {
  sim::SimConfig cfg = sim::make_scenario("random_motion", kRateHz, seed);
  cfg.duration_s = kScoredToS + 0.5;
  const testing::FieldRotation rotation{amplitude_deg * kRadPerDeg, kRotationPeriodS, kRotationStartS};
  testing::RotatedFieldSim simu(cfg, rotation);
  ParallelKf kf(told(cfg, adaptive));
  double sum = 0.0;
  double sum_rot = 0.0;
  int n = 0;
  int covered = 0;
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    if (!kf.update(s.imu) || s.truth.t_s < kScoredFromS || s.truth.t_s > kScoredToS) {
      continue;
    }
    const ParallelKfOutput out = kf.output();
    const Eigen::Vector3d e = world_attitude_error(out.q_world_body, s.truth.q_world_body);
    covered += std::abs(e.z()) <= kZ95 * std::sqrt(kf.attitude_covariance(out)(2, 2)) ? 1 : 0;
    sum += e.z() * e.z();
    sum_rot += rotation.at(s.truth.t_s) * rotation.at(s.truth.t_s);
    ++n;
  }
  return {std::sqrt(sum / n) * kDegPerRad, std::sqrt(sum_rot / n) * kDegPerRad,
          static_cast<double>(covered) / static_cast<double>(n)};
}

// KF2 weighs an accepted field against sigma_M plus the disturbance variance its innovation shows
// (mag_adaptive_noise). The rotation here varies faster than the clean-field lag tau0 (omega tau0 >=
// 1 for tau0 >= period / 2 pi = 3.2 s; measured about 5 s), so the heading follows the rotation
// low-passed, a share 1 / sqrt(1 + (omega tau)^2) of it. The certain part of the disturbance
// variance is the heading error it leaves, here at least (2 deg)^2, against the white direction
// noise 2 sigma_M^2 / (m cos(dip))^2, about (1 deg)^2: it at least doubles the measurement noise,
// so the lag grows at least by sqrt(2) (a steady-state KF's lag goes as sqrt(R / Q)), and the share
// falls at least to sqrt((1 + x^2) / (1 + 2 x^2)) of the clean lag's, x = omega tau0 >= 1: at most
// sqrt(2 / 3) = 0.816 of the error of the same filter weighing sigma_M alone (measured 0.59-0.60).
constexpr double kMaxShareOfWhiteOnly = 0.816;

TEST(ParallelKfTurnedField, GivenAFieldTurningHorizontallyWhereTheSensorMovesWhenKf2WeighsTheDisturbanceItsInnovationShowsThenTheHeadingFollowsLessOfIt) {
  for (int r = 0; r < kRuns; ++r) {
    // GIVEN random motion in a field turning horizontally by up to kRotationDeg (norm and dip kept)
    const uint64_t seed = 4000 + static_cast<uint64_t>(r);
    // WHEN the filter weighs the disturbance, and (control) weighs sigma_M alone
    const HeadingFigures adaptive = run(seed, true);
    const HeadingFigures white_only = run(seed, false);
    std::printf("seed %llu: heading RMS %.3f deg (sigma_M alone %.3f), rotation RMS %.3f deg; %.1f %% inside the "
                "published 95 %% heading bound (sigma_M alone %.1f %%)\n",
                static_cast<unsigned long long>(seed), adaptive.rms_deg, white_only.rms_deg, adaptive.rotation_rms_deg,
                100.0 * adaptive.covered, 100.0 * white_only.covered);
    // THEN its heading error against the truth is at most kMaxShareOfWhiteOnly of the control's
    EXPECT_LE(adaptive.rms_deg, kMaxShareOfWhiteOnly * white_only.rms_deg) << "seed " << seed;
    // (Printed, not asserted: the published heading's coverage here is 83.9 / 84.7 % with the
    // adaptive noise against 100 % with sigma_M alone, just under the 85 %. The noise it
    // adds is the disturbance's certain part only, and the slow rotation's error it leaves is
    // correlated, which KF2's own covariance takes as white. An open gap (docs/ESTIMATORS.md "A
    // field turned in the room"); BROAD trial 30 is 94.3 % inside with it.)
  }
}

// In a field that does not turn, KF2's innovation shows nothing beyond the white noise and the
// attitude error: the estimate is the one of sigma_M alone (the heading RMS equal to
// kSameHeadingDeg, rounding only).
constexpr double kSameHeadingDeg = 1e-9;

TEST(ParallelKfTurnedField, GivenACleanFieldWhenKf2WeighsTheDisturbanceItsInnovationShowsThenTheHeadingIsAsWithSigmaMAlone) {
  for (int r = 0; r < kRuns; ++r) {
    const uint64_t seed = 4000 + static_cast<uint64_t>(r);
    const HeadingFigures adaptive = run(seed, true, 0.0);
    const HeadingFigures white_only = run(seed, false, 0.0);
    EXPECT_NEAR(adaptive.rms_deg, white_only.rms_deg, kSameHeadingDeg) << "seed " << seed;
  }
}

}  // namespace
}  // namespace poise
