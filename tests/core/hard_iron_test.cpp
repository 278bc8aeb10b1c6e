// The online hard-iron offset (poise/core/hard_iron.h). Oracle: a simulated body turned by a known
// angular rate in a uniform world field, with a known body-frame offset added to every reading:
// m_body = R^T m_world + b. The estimator sees only the gyro and the readings.
#include "poise/core/hard_iron.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>

namespace poise {
namespace {

constexpr double kRateHz = 200.0;
const Eigen::Vector3d kWorldField(0.0, 16.0, -41.0);  // uT, ENU: north and down, dip about 69 deg
constexpr double kReadingNoiseUt = 0.5;                 // per axis, 1 sigma
constexpr double kConvergedTolUt = 0.5;                 // |b_hat - b| after 20 s of rotation

// A rate that turns the body about every axis in turn (rad/s), smooth in time.
Eigen::Vector3d tumbling_rate(double t) {
  return {1.5 * std::sin(0.7 * t), 1.2 * std::cos(0.45 * t), 0.9 * std::sin(0.31 * t + 1.0)};
}

struct Sim {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();  // q_world_body
  std::mt19937 rng{42};
  std::normal_distribution<double> noise{0.0, kReadingNoiseUt};
  int64_t k = 0;

  // The sample at step k; the body turns at w(t) over the step (exactly, in small sub-steps).
  ImuSample next(const Eigen::Vector3d& offset, Eigen::Vector3d (*rate)(double)) {
    const double t = static_cast<double>(k) / kRateHz;
    if (k > 0) {
      constexpr int kSub = 20;
      for (int i = 0; i < kSub; ++i) {
        const double ti = t - (1.0 - (i + 0.5) / kSub) / kRateHz;
        const Eigen::Vector3d rot = rate(ti) / (kRateHz * kSub);
        if (rot.norm() > 0.0) {
          q = (q * Eigen::Quaterniond(Eigen::AngleAxisd(rot.norm(), rot.normalized()))).normalized();
        }
      }
    }
    ImuSample s;
    s.stamp_ns = static_cast<int64_t>(std::llround(t * 1e9));
    s.gyro_rps = rate(t);
    s.has_mag = true;
    s.mag_ut = q.conjugate() * kWorldField + offset +
               Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    ++k;
    return s;
  }
};

Eigen::Vector3d still(double /*t*/) { return Eigen::Vector3d::Zero(); }

TEST(HardIron, GivenATumblingSensorWithAKnownOffsetWhenFedTwentySecondsThenTheEstimateIsWithinTolerance) {
  const Eigen::Vector3d b(12.0, -25.0, 40.0);
  HardIronEstimator h;
  Sim sim;
  for (int i = 0; i < static_cast<int>(20 * kRateHz); ++i) {
    h.update(sim.next(b, tumbling_rate));
  }
  EXPECT_LT((h.offset_ut() - b).norm(), kConvergedTolUt) << h.offset_ut().transpose();
  EXPECT_TRUE(h.converged());
  EXPECT_TRUE(h.applied());
  EXPECT_GT(h.report().count(HardIronStep::kUpdated), 0U);
  // The covariance is not overconfident: each axis' error within 4 sigma.
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT(std::abs(h.offset_ut()[i] - b[i]), 4.0 * h.sigma_ut()[i] + 0.05) << "axis " << i;
  }
  const Eigen::Vector3d m(1.0, 2.0, 3.0);
  EXPECT_TRUE(h.corrected(m).isApprox(m - h.offset_ut()));
}

// A filter hands its own gyro-only orientation (the parallel KF's R_ib) instead of the estimator
// integrating the gyro again. Oracle: the simulator's true orientation handed in, in a frame turned
// by an arbitrary constant rotation (only R_k^T R_j may matter), and the known offset.
TEST(HardIron, GivenTheOrientationHandedInWhenTumblingWithAKnownOffsetThenTheEstimateIsWithinTolerance) {
  const Eigen::Vector3d b(-6.0, 1.0, 58.0);  // about trial 32's attached magnet, uT
  const Eigen::Matrix3d frame = Eigen::AngleAxisd(2.0, Eigen::Vector3d(1.0, 2.0, 3.0).normalized()).toRotationMatrix();
  HardIronEstimator h;
  Sim sim;
  for (int i = 0; i < static_cast<int>(20 * kRateHz); ++i) {
    const ImuSample s = sim.next(b, tumbling_rate);
    h.update(s.stamp_ns, Eigen::Matrix3d(frame * sim.q.toRotationMatrix()), s.gyro_rps, s.mag_ut);
  }
  EXPECT_LT((h.offset_ut() - b).norm(), kConvergedTolUt) << h.offset_ut().transpose();
  EXPECT_TRUE(h.applied());
  EXPECT_EQ(h.report().count(HardIronStep::kGated), 0U);
  EXPECT_GT(h.report().count(HardIronStep::kInterval), 0U);  // the samples between comparisons
  // a non-finite orientation is refused and counted where it would be used, never fused
  HardIronEstimator g;
  const Eigen::Matrix3d nan = Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN());
  EXPECT_EQ(g.update(0, nan, Eigen::Vector3d::Zero(), kWorldField).step, HardIronStep::kRejectedInput);
  EXPECT_EQ(g.update(0, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), kWorldField).step,
            HardIronStep::kWarmingUp);
  for (int64_t t_ns = 10'000'000; t_ns < 250'000'000; t_ns += 10'000'000) {  // inside the 0.25 s interval
    EXPECT_EQ(g.update(t_ns, nan, Eigen::Vector3d::Zero(), kWorldField).step, HardIronStep::kInterval);
  }
  EXPECT_EQ(g.update(250'000'000, nan, Eigen::Vector3d::Zero(), kWorldField).step, HardIronStep::kRejectedInput);
  EXPECT_TRUE(g.offset_ut().allFinite());
  EXPECT_TRUE(g.covariance().allFinite());
}

// Rate independence: the readings compared are taken at multiples of lag_s (interpolated between
// the two samples around each), not at whichever sample comes first after lag_s, so the same
// motion sampled at 285.7 Hz and at 1 kHz gives the same comparisons. Oracle: a field that is a
// smooth function of time (a known offset plus a 1.5 uT, 40 rad/s ripple that stands in for noise,
// so the estimate is not exact), the true orientation handed in; the two estimates must agree far
// closer than the ripple moves in the 2 ms by which the old pairing's instants differed (0.12 uT).
TEST(HardIron, GivenTheSameMotionAt285HzAnd1kHzWhenFedThenTheEstimatesAgree) {
  constexpr double kRunS = 20.1;  // both rates have a sample after the grid instant at 20 s
  constexpr double kAgreeUt = 0.02;  // |b(285.7 Hz) - b(1 kHz)|, uT (interpolation error ~0.004 uT)
  const Eigen::Vector3d b(12.0, -25.0, 40.0);
  auto run = [&](double rate_hz) {
    HardIronEstimator h;
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    const auto n = static_cast<int>(kRunS * rate_hz);
    for (int k = 0; k <= n; ++k) {
      const double t = k / rate_hz;
      if (k > 0) {
        constexpr int kSub = 20;  // the truth over the step, rate at each sub-step's midpoint
        for (int i = 0; i < kSub; ++i) {
          const Eigen::Vector3d w = tumbling_rate(t - (1.0 - (i + 0.5) / kSub) / rate_hz);
          q = (q * Eigen::Quaterniond(Eigen::AngleAxisd(w.norm() / (rate_hz * kSub), w.normalized()))).normalized();
        }
      }
      const Eigen::Vector3d ripple(std::sin(40.0 * t), std::sin(40.0 * t + 2.0), std::sin(40.0 * t + 4.0));
      const Eigen::Vector3d m = q.conjugate() * kWorldField + b + 1.5 * ripple;
      h.update(static_cast<int64_t>(std::llround(t * 1e9)), q.toRotationMatrix(), tumbling_rate(t), m);
    }
    return h;
  };
  const HardIronEstimator slow = run(2000.0 / 7.0);
  const HardIronEstimator fast = run(1000.0);
  EXPECT_LT((slow.offset_ut() - fast.offset_ut()).norm(), kAgreeUt)
      << slow.offset_ut().transpose() << " against " << fast.offset_ut().transpose();
  EXPECT_EQ(slow.report().count(HardIronStep::kUpdated) + slow.report().count(HardIronStep::kGated),
            fast.report().count(HardIronStep::kUpdated) + fast.report().count(HardIronStep::kGated));
  EXPECT_LT((fast.offset_ut() - b).norm(), 1.0);  // and both near the offset (the ripple is 1.5 uT)
}

TEST(HardIron, GivenAStillSensorWhenFedThenNothingIsLearntAndTheReportSaysNotEnoughRotation) {
  HardIronEstimator h;
  Sim sim;
  for (int i = 0; i < static_cast<int>(10 * kRateHz); ++i) {
    h.update(sim.next(Eigen::Vector3d(30.0, 0.0, 0.0), still));
  }
  EXPECT_EQ(h.report().count(HardIronStep::kUpdated), 0U);
  EXPECT_GT(h.report().count(HardIronStep::kNotEnoughRotation), 0U);
  EXPECT_EQ(h.offset_ut(), Eigen::Vector3d::Zero());
  EXPECT_FALSE(h.converged());
  const Eigen::Vector3d m(1.0, 2.0, 3.0);
  EXPECT_EQ(h.corrected(m), m);
}

// A step of the offset (a magnet put on) with the body not turning (step_detection, off by
// default): the comparisons cannot see a constant offset, but the step shows between two readings
// whatever the rotation, m_k - C m_j = b_new - b_old (session 26). Oracle: the offset the simulator adds. The step's estimate is the
// mean of two comparisons sharing their earlier reading: its error per axis has the sigma
// sqrt(s^2 + (s^2 + s^2) / 4) for the readings' noise s.
constexpr double kStepSigmaUt = 0.612;  // sqrt(1.5) x kReadingNoiseUt
constexpr double kStepTolUt = 4.0 * kStepSigmaUt;

/// Feeds a still sensor: no offset until `on_s`, then `offset` (with `first` for the one sample at
/// on_s exactly: a magnet caught half-way), for `run_s` in all.
HardIronEstimator still_with_step(const Eigen::Vector3d& offset, double on_s, double run_s,
                                  const Eigen::Vector3d& first, bool step_detection = true) {
  HardIronParams p;
  p.step_detection = step_detection;
  HardIronEstimator h(p);
  Sim sim;
  for (int i = 0; i < static_cast<int>(run_s * kRateHz); ++i) {
    const double t = static_cast<double>(i) / kRateHz;
    const bool at_on = std::abs(t - on_s) < 0.5 / kRateHz;
    h.update(sim.next(t < on_s && !at_on ? Eigen::Vector3d::Zero() : (at_on ? first : offset), still));
  }
  return h;
}

TEST(HardIron, GivenAStillSensorWhenAMagnetIsPutOnThenTheStepIsTakenAsTheOffsetAndApplied) {
  // GIVEN a still sensor with no offset, then a 10 uT offset from 5.13 s (between grid instants)
  const Eigen::Vector3d b(8.0, -5.0, 3.5);
  // WHEN fed 8 s
  const HardIronEstimator h = still_with_step(b, 5.13, 8.0, b);
  // THEN one step was taken, the estimate is the offset within the step's noise, and it is applied
  EXPECT_EQ(h.report().count(HardIronStep::kStep), 1U);
  EXPECT_EQ(h.report().count(HardIronStep::kUpdated), 0U);  // nothing turned
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(h.offset_ut()[i], b[i], kStepTolUt) << "axis " << i;
  }
  EXPECT_TRUE(h.applied());
  // and without step_detection (the default) nothing is learnt without a turn
  const HardIronEstimator off = still_with_step(b, 5.13, 8.0, b, HardIronParams{}.step_detection);
  EXPECT_EQ(off.report().count(HardIronStep::kStep), 0U);
  EXPECT_FALSE(off.report().present);
}

TEST(HardIron, GivenAMagnetCaughtHalfWayAtAGridInstantWhenStillThenTheWholeStepIsTaken) {
  // GIVEN the same step with the one reading at the grid instant 5 s half-way (a magnet put on over
  // a few samples): the comparisons each side of 5 s see half of it
  const Eigen::Vector3d b(-6.0, 7.0, 4.0);
  // WHEN fed 8 s
  const HardIronEstimator h = still_with_step(b, 5.0, 8.0, 0.5 * b);
  // THEN the step is taken whole (against the reading before the half-way one)
  EXPECT_EQ(h.report().count(HardIronStep::kStep), 1U);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(h.offset_ut()[i], b[i], kStepTolUt) << "axis " << i;
  }
  EXPECT_TRUE(h.applied());
}

TEST(HardIron, GivenATransientFieldWhenStillThenNoStepIsTaken) {
  // GIVEN a still sensor whose field jumps by 20 uT for 0.3 s and comes back (a tap, a magnet
  // passing by), twice
  HardIronParams p;
  p.step_detection = true;
  HardIronEstimator h(p);
  Sim sim;
  for (int i = 0; i < static_cast<int>(8.0 * kRateHz); ++i) {
    const double t = static_cast<double>(i) / kRateHz;
    const bool jump = (t >= 3.1 && t < 3.4) || (t >= 5.9 && t < 6.2);
    h.update(sim.next(jump ? Eigen::Vector3d(0.0, 20.0, 0.0) : Eigen::Vector3d::Zero(), still));
  }
  // THEN no step is taken and nothing is applied
  EXPECT_EQ(h.report().count(HardIronStep::kStep), 0U);
  EXPECT_FALSE(h.applied());
  EXPECT_FALSE(h.report().present);
}

TEST(HardIron, GivenACleanSensorWhenTumbledThenTheEstimateStaysNearZeroAndIsNotApplied) {
  HardIronEstimator h;
  Sim sim;
  for (int i = 0; i < static_cast<int>(20 * kRateHz); ++i) {
    h.update(sim.next(Eigen::Vector3d::Zero(), tumbling_rate));
  }
  EXPECT_TRUE(h.converged());
  EXPECT_LT(h.offset_ut().norm(), kConvergedTolUt);
  EXPECT_FALSE(h.applied()) << "|b| " << h.offset_ut().norm() << " <= min_applied_ut "
                            << h.params().min_applied_ut;
}

// error_covariance(): b's error under the reading noise the comparisons show (noise_tau_s), the
// gains, gate and convergence staying covariance()'s. Oracle: the spread of b_hat - b over seeds of
// the simulated sensor, whose reading noise is known, against the mean published 3 x 3's diagonal,
// pooled over the three axes (3 x kSeeds squares: the ratio's 1-sigma about 0.13). The simulated
// offset is constant, so the estimator is told no walk (the walk is the same in both covariances).
struct SpreadCase {
  double reading_sigma_ut;  // the simulated sensor's noise per axis
  double spread_ratio = 0;  // sum of the squared errors over the sum of error_covariance()'s variances
  double model_ratio = 0;   // the same against covariance()'s
  double noise_ratio = 0;   // mean noise_ratio() at the end
};

void run_spread(SpreadCase& c) {
  constexpr int kSeeds = 40;
  const Eigen::Vector3d b(12.0, -25.0, 40.0);
  double e2 = 0.0, v_err = 0.0, v_model = 0.0, ratio = 0.0;
  HardIronParams p;
  p.walk_ut_per_sqrt_s = 0.0;
  for (int seed = 0; seed < kSeeds; ++seed) {
    HardIronEstimator h(p);
    Sim sim;
    sim.rng.seed(1000 + seed);
    sim.noise = std::normal_distribution<double>(0.0, c.reading_sigma_ut);
    for (int i = 0; i < static_cast<int>(20 * kRateHz); ++i) {
      h.update(sim.next(b, tumbling_rate));
    }
    e2 += (h.offset_ut() - b).squaredNorm();
    v_err += h.error_covariance().trace();
    v_model += h.covariance().trace();
    ratio += h.noise_ratio() / kSeeds;
  }
  c.spread_ratio = e2 / v_err;
  c.model_ratio = e2 / v_model;
  c.noise_ratio = ratio;
}

TEST(HardIron, GivenReadingsQuieterThanTheModelsNoiseWhenTumbledThenTheErrorCovarianceMatchesTheSpreadOverSeeds) {
  constexpr double kSpreadLo = 0.6;  // 3 sigma of a 120-square mean about 1
  constexpr double kSpreadHi = 1.5;
  // 0.5 uT against the model's 1.5 uT (noise_ut): the model's variance is 9 times the noise's
  SpreadCase quiet{kReadingNoiseUt};
  run_spread(quiet);
  EXPECT_GT(quiet.spread_ratio, kSpreadLo);
  EXPECT_LT(quiet.spread_ratio, kSpreadHi);
  EXPECT_LT(quiet.model_ratio, 0.25) << "covariance() is the model noise's, far above the spread";
  EXPECT_NEAR(quiet.noise_ratio, (kReadingNoiseUt * kReadingNoiseUt) / (1.5 * 1.5), 0.05);
  // readings as noisy as the model says: the spread is error_covariance()'s, and covariance() is
  // still far above it (a reading is in two comparisons; it takes their noises as independent)
  SpreadCase model{HardIronParams{}.noise_ut};
  run_spread(model);
  EXPECT_GT(model.spread_ratio, kSpreadLo);
  EXPECT_LT(model.spread_ratio, kSpreadHi);
  EXPECT_LT(model.model_ratio, 0.25);
  EXPECT_NEAR(model.noise_ratio, 1.0, 0.1);
  std::printf("spread / error_covariance: %.3f (0.5 uT), %.3f (1.5 uT); spread / covariance: %.3f, %.3f; "
              "noise_ratio %.3f, %.3f\n",
              quiet.spread_ratio, model.spread_ratio, quiet.model_ratio, model.model_ratio, quiet.noise_ratio,
              model.noise_ratio);
}

TEST(HardIron, GivenTheOffsetRemovedMidRunWhenTumblingThenItResetsAndLearnsZero) {
  HardIronEstimator h;
  Sim sim;
  for (int i = 0; i < static_cast<int>(20 * kRateHz); ++i) {
    h.update(sim.next(Eigen::Vector3d(30.0, -10.0, 20.0), tumbling_rate));
  }
  ASSERT_TRUE(h.applied());
  for (int i = 0; i < static_cast<int>(20 * kRateHz); ++i) {
    h.update(sim.next(Eigen::Vector3d::Zero(), tumbling_rate));
  }
  EXPECT_GE(h.report().count(HardIronStep::kReset), 1U);
  EXPECT_LT(h.offset_ut().norm(), kConvergedTolUt);
  EXPECT_FALSE(h.applied());
}

// The consistency check (consistency_tau_s): an offset that the readings no longer carry is not
// removed, although the estimate still holds it. Oracle: the simulator knows when the offset is
// real. The gate is opened wide and resets are off so that the estimate keeps the old offset and
// only decays (a Kalman filter with a small covariance): what stops the correction is the check,
// not the gate and not min_applied_ut.
TEST(HardIron, GivenAnOffsetTheReadingsNoLongerCarryWhenTheEstimateStillHoldsItThenItIsNotApplied) {
  constexpr double kRealS = 20.0;      // the offset is on this long, then gone, s
  constexpr double kSwitchOffS = 5.0;  // the check must stop the correction within this, s (tau 5 s: about 3.5 s)
  for (const double tau_s : {5.0, 0.0}) {
    HardIronParams p;
    p.gate_chi2 = 1e12;
    p.reset_after_s = 1e3;
    p.removed_log_lr = 0.0;  // the consistency check alone (the removal test is below)
    p.consistency_tau_s = tau_s;
    HardIronEstimator h(p);
    Sim sim;
    for (int i = 0; i < static_cast<int>(kRealS * kRateHz); ++i) {
      h.update(sim.next(Eigen::Vector3d(30.0, -10.0, 20.0), tumbling_rate));
    }
    ASSERT_TRUE(h.applied()) << "tau " << tau_s;
    if (tau_s > 0.0) {  // while the offset was real, removing it made the magnitude more constant
      EXPECT_LT(h.report().corrected_norm_change_ut, h.report().raw_norm_change_ut);
    }
    for (int i = 0; i < static_cast<int>(kSwitchOffS * kRateHz); ++i) {
      h.update(sim.next(Eigen::Vector3d::Zero(), tumbling_rate));
    }
    ASSERT_GT(h.offset_ut().norm(), p.min_applied_ut) << "tau " << tau_s << ": the estimate still holds an offset";
    EXPECT_TRUE(h.converged());
    EXPECT_EQ(h.report().count(HardIronStep::kReset), 0U);
    if (tau_s > 0.0) {
      EXPECT_FALSE(h.applied()) << "the correction of an offset that is gone makes the magnitude vary";
      EXPECT_GT(h.report().corrected_norm_change_ut, h.report().raw_norm_change_ut);
    } else {
      EXPECT_TRUE(h.applied()) << "without the check the stale offset is still removed";
    }
  }
}

TEST(HardIron, GivenAnOffsetThatIsRemovedWhenNoInnovationIsRefusedThenTheRemovalTestDropsTheEstimate) {
  // GIVEN a 37 uT offset on for 20 s, then gone, the chi-square reset out of the way (as above)
  constexpr double kRealS = 20.0;   // s
  constexpr double kDroppedS = 5.0;  // the estimate must be dropped within this after the removal, s
  HardIronParams p;
  p.gate_chi2 = 1e12;
  p.reset_after_s = 1e3;
  p.consistency_tau_s = 0.0;  // the removal test alone
  HardIronEstimator h(p);
  Sim sim;
  for (int i = 0; i < static_cast<int>(kRealS * kRateHz); ++i) {
    h.update(sim.next(Eigen::Vector3d(30.0, -10.0, 20.0), tumbling_rate));
  }
  ASSERT_TRUE(h.applied());
  EXPECT_EQ(h.report().count(HardIronStep::kReset), 0U) << "no false alarm while the offset is there";
  // WHEN the readings no longer carry it
  for (int i = 0; i < static_cast<int>(kDroppedS * kRateHz); ++i) {
    h.update(sim.next(Eigen::Vector3d::Zero(), tumbling_rate));
  }
  // THEN the CUSUM of "no offset" against the estimate reached removed_log_lr: b dropped, learnt again
  EXPECT_GE(h.report().count(HardIronStep::kReset), 1U);
  EXPECT_LT(h.offset_ut().norm(), p.min_applied_ut);
  EXPECT_FALSE(h.applied());
}

// A slow turn about one axis (rad/s): 0.1 rad/s turns the body 0.025 rad over lag_s, so a
// comparison of readings lag_s apart sees (I - C) b of 0.2 uT for an 8 uT offset, below the noise.
Eigen::Vector3d slow_rate(double /*t*/) { return {0.0, 0.0, 0.1}; }

// The removal test judges each grid reading against the field followed in the gyro frame: once the
// magnet is gone, "no offset" fits and the estimate misses by |b| whatever the body's rate. Oracle:
// the simulator knows when the offset is removed. The bound on the time to drop it is derived from
// the test's own statistics: after the removal each reading adds at least
// 0.5 (|b|^2 / v - 3) to the CUSUM (the estimate's residual |b| against a variance v, at most twice
// the reading's noise_ut^2 for the reading plus the field's mean, less the no-offset residual's
// expected 3 dof), so removed_log_lr is reached after n = ceil(h / that) readings, lag_s apart,
// plus one lag_s for the grid instant after the removal and one for the comparison that starts.
TEST(HardIron, GivenAnOffsetRemovedInSlowMotionWhenTheReadingsNoLongerCarryItThenTheEstimateIsDroppedWithinTheDerivedTime) {
  const Eigen::Vector3d b(6.0, -4.0, 3.5);  // 8.0 uT, the size the sweep lost 15-20 s on
  constexpr double kTumbleS = 20.0;          // learnt while tumbling, s
  constexpr double kSlowWithMagnetS = 10.0;  // then slow motion with the magnet still on, s
  HardIronParams p;
  HardIronEstimator h(p);
  Sim sim;
  for (int i = 0; i < static_cast<int>(kTumbleS * kRateHz); ++i) {
    h.update(sim.next(b, tumbling_rate));
  }
  ASSERT_TRUE(h.applied());
  ASSERT_LT((h.offset_ut() - b).norm(), kConvergedTolUt);
  // GIVEN slow motion with the magnet still on: no false alarm, the estimate stays applied
  for (int i = 0; i < static_cast<int>(kSlowWithMagnetS * kRateHz); ++i) {
    h.update(sim.next(b, slow_rate));
  }
  EXPECT_EQ(h.report().count(HardIronStep::kReset), 0U) << "no false alarm while the offset is there";
  ASSERT_TRUE(h.applied());
  // WHEN the magnet is removed, the body still turning slowly
  const double v = 2.0 * p.noise_ut * p.noise_ut;  // uT^2, per axis
  const double llr_per_reading = 0.5 * (b.squaredNorm() / v - 3.0);
  ASSERT_GT(llr_per_reading, 0.0);
  const double dropped_within_s = p.lag_s * (std::ceil(p.removed_log_lr / llr_per_reading) + 2.0);
  double dropped_after_s = std::numeric_limits<double>::infinity();
  constexpr double kWatchS = 30.0;  // s (the old test of readings lag_s apart: not dropped in this)
  for (int i = 0; i < static_cast<int>(kWatchS * kRateHz); ++i) {
    h.update(sim.next(Eigen::Vector3d::Zero(), slow_rate));
    if (!h.applied()) {
      dropped_after_s = (i + 1) / kRateHz;
      break;
    }
  }
  // THEN it is dropped (b = 0, learnt again) within the derived time, and the reading is used as it is
  EXPECT_LE(dropped_after_s, dropped_within_s) << "bound " << dropped_within_s << " s";
  EXPECT_EQ(h.report().count(HardIronStep::kReset), 1U);
  EXPECT_LT(h.offset_ut().norm(), p.min_applied_ut);
  const Eigen::Vector3d m(1.0, 2.0, 3.0);
  EXPECT_EQ(h.corrected(m), m);
}

TEST(HardIron, GivenHostileReadingsWhenFedThenEachIsRejectedCountedAndTheEstimateUntouched) {
  HardIronEstimator h;
  Sim sim;
  for (int i = 0; i < static_cast<int>(5 * kRateHz); ++i) {
    h.update(sim.next(Eigen::Vector3d(5.0, 5.0, 5.0), tumbling_rate));
  }
  const Eigen::Vector3d b = h.offset_ut();
  const Eigen::Matrix3d P = h.covariance();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  ImuSample s = sim.next(Eigen::Vector3d::Zero(), tumbling_rate);
  const Eigen::Vector3d hostile_mag[] = {{nan, 0, 0}, {1e308, 1e308, 1e308}, {0, -inf, 0}, {1e4, 0, 0}};
  for (const auto& m : hostile_mag) {
    ImuSample x = s;
    x.mag_ut = m;
    EXPECT_EQ(h.update(x).step, HardIronStep::kRejectedInput) << m.transpose();
  }
  const Eigen::Vector3d hostile_gyro[] = {{nan, 0, 0}, {1e308, 0, 0}, {0, 0, inf}};
  for (const auto& w : hostile_gyro) {
    ImuSample x = s;
    x.gyro_rps = w;
    EXPECT_EQ(h.update(x).step, HardIronStep::kRejectedInput) << w.transpose();
  }
  // stamps no sensor clock reads (before 0; the year 292277026596, INT64_MAX ns): refused as the
  // cores' check_imu_sample refuses them, before any stamp difference is formed
  const int64_t hostile_stamp[] = {-1, std::numeric_limits<int64_t>::max(), std::numeric_limits<int64_t>::min()};
  for (const int64_t t : hostile_stamp) {
    ImuSample x = s;
    x.stamp_ns = t;
    EXPECT_EQ(h.update(x).step, HardIronStep::kRejectedInput) << t;
    EXPECT_EQ(h.update(t, Eigen::Matrix3d::Identity(), x.gyro_rps, x.mag_ut).step, HardIronStep::kRejectedInput) << t;
  }
  ImuSample no_mag = s;
  no_mag.has_mag = false;
  EXPECT_EQ(h.update(no_mag).step, HardIronStep::kNoMagnetometer);
  EXPECT_EQ(h.report().count(HardIronStep::kRejectedInput), 13U);
  EXPECT_EQ(h.offset_ut(), b);
  EXPECT_EQ(h.covariance(), P);
  // A stamp that goes back is a gap, not a comparison.
  ImuSample back = s;
  back.stamp_ns -= 1000000000;
  h.update(s);
  EXPECT_EQ(h.update(back).step, HardIronStep::kGap);
}

// The estimator refuses p, and the message names the key ("hard_iron parameter <key>").
void expect_refused_naming(const HardIronParams& p, const std::string& key) {
  try {
    HardIronEstimator h(p);
    FAIL() << "accepted a bad " << key;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("hard_iron parameter " + key), std::string::npos) << e.what();
  }
}

TEST(HardIronParams, GivenABadValueOfAKeyWhenConstructedThenTheMessageNamesIt) {
  HardIronParams p;
  p.noise_ut = -1.0;
  expect_refused_naming(p, "noise_ut");
  HardIronParams q;
  q.lag_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(HardIronEstimator{q}, std::invalid_argument);
  // a lag below 1 ms would make the grid of readings a zero (or a per-ns) step; squared 1e308s overflow
  HardIronParams tiny;
  tiny.lag_s = 1e-12;
  EXPECT_THROW(HardIronEstimator{tiny}, std::invalid_argument);
  HardIronParams huge;
  huge.prior_sigma_ut = 1e308;
  EXPECT_THROW(HardIronEstimator{huge}, std::invalid_argument);
  HardIronParams window;
  window.noise_tau_s = -1.0;
  expect_refused_naming(window, "noise_tau_s");
}

}  // namespace
}  // namespace poise
