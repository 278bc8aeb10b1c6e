// The magnetic field gate shared by the parallel KF and the selective EKF (poise/core/field_gate.h).
// Oracles: the field is generated from a known magnitude and dip, so the learnt reference, the
// gate's decisions and the reference's first-order following are known in closed form.
#include "poise/core/attitude.h"
#include "poise/core/field_gate.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

namespace poise {
namespace {

constexpr double kDt = 0.01;  // 100 Hz
const Eigen::Vector3d kUp(0.0, 0.0, 1.0);

// A field of magnitude m_ut with dip dip_deg below the horizontal, pointing north (+x) in a body
// whose up is +z.
Eigen::Vector3d field(double m_ut, double dip_deg) {
  const double d = dip_deg * kRadPerDeg;
  return {m_ut * std::cos(d), 0.0, -m_ut * std::sin(d)};
}

FieldGate learnt_gate(const FieldGateParams& p, double m_ut, double dip_deg) {
  FieldGate g;
  g.reset(p);
  g.step(p, field(m_ut, dip_deg), kUp, 0.0);
  for (int k = 0; k < 200 && !g.learnt; ++k) {
    EXPECT_EQ(g.step(p, field(m_ut, dip_deg), kUp, kDt), FieldVerdict::kLearning);
  }
  return g;
}

TEST(FieldGate, GivenAStartupWindowWhenTheFieldIsSteadyThenItsMagnitudeAndDipAreLearnt) {
  const FieldGateParams p;  // startup 1 s
  const FieldGate g = learnt_gate(p, 48.0, 62.0);
  EXPECT_TRUE(g.learnt);
  EXPECT_NEAR(g.m_ut, 48.0, 1e-9);                   // uT
  EXPECT_NEAR(g.dip_rad * kDegPerRad, 62.0, 1e-9);   // deg
  EXPECT_NEAR(g.learn_time_s, p.startup_s, kDt + 1e-12);
}

TEST(FieldGate, GivenALearntFieldWhenTheNormOrTheDipLeavesTheToleranceThenTheSampleIsGatedAndCounted) {
  FieldGateParams p;
  p.norm_tol = 0.05;
  p.dip_tol_deg = 10.0;
  p.reference_tau_s = 0.0;
  FieldGate g = learnt_gate(p, 50.0, 60.0);
  EXPECT_EQ(g.step(p, field(52.0, 60.0), kUp, kDt), FieldVerdict::kAccepted);  // +4 %
  EXPECT_EQ(g.step(p, field(53.0, 60.0), kUp, kDt), FieldVerdict::kGated);     // +6 %
  EXPECT_EQ(g.step(p, field(50.0, 69.0), kUp, kDt), FieldVerdict::kAccepted);  // +9 deg
  EXPECT_EQ(g.step(p, field(50.0, 71.0), kUp, kDt), FieldVerdict::kGated);     // +11 deg
  EXPECT_EQ(g.step(p, field(50.0, 49.0), kUp, kDt), FieldVerdict::kGated);     // -11 deg
  EXPECT_EQ(g.gated, 2u + 1u);
  // the dip is measured against the up axis given, whatever its length
  EXPECT_EQ(g.step(p, field(50.0, 60.0), 3.0 * kUp, kDt), FieldVerdict::kAccepted);
}

TEST(FieldGate, GivenNoNormToleranceWhenTheNormChangesThenOnlyTheDipIsTested) {
  FieldGateParams p;
  p.norm_tol = 0.0;  // 0 = no norm test
  FieldGate g = learnt_gate(p, 50.0, 60.0);
  EXPECT_EQ(g.step(p, field(80.0, 60.0), kUp, kDt), FieldVerdict::kAccepted);
  EXPECT_EQ(g.step(p, field(50.0, 75.0), kUp, kDt), FieldVerdict::kGated);
}

TEST(FieldGate, GivenAFieldThatStepsWithinTheGateWhenItIsAcceptedThenTheReferenceFollowsItWithTheTimeConstant) {
  FieldGateParams p;
  p.reference_tau_s = 50.0;
  FieldGate g = learnt_gate(p, 50.0, 60.0);
  const double t_s = 50.0;  // one time constant
  for (int k = 0; k < static_cast<int>(t_s / kDt); ++k) {
    EXPECT_EQ(g.step(p, field(51.0, 60.0), kUp, kDt), FieldVerdict::kAccepted);
    g.tick(p, kDt);
  }
  // first-order: 1 uT step, 1 - exp(-1) of it after tau; the window updates (40 ms) make it a
  // discrete first order whose difference from the continuous one is below 0.1 % of the step.
  const double expected = 50.0 + 1.0 * (1.0 - std::exp(-t_s / p.reference_tau_s));
  EXPECT_NEAR(g.m_ut, expected, 0.002);  // uT
}

TEST(FieldGate, GivenAGatedFieldWhenTheReferenceFollowsThenGatedSamplesNeverMoveIt) {
  FieldGateParams p;
  p.reacquire_s = 0.0;
  p.max_reject_s = 0.0;
  FieldGate g = learnt_gate(p, 50.0, 60.0);
  for (int k = 0; k < 3000; ++k) {  // 30 s of a +30 % field
    EXPECT_EQ(g.step(p, field(65.0, 60.0), kUp, kDt), FieldVerdict::kGated);
    g.tick(p, kDt);
  }
  EXPECT_NEAR(g.m_ut, 50.0, 1e-12);
}

TEST(FieldGate, GivenANewStableFieldWhenItIsGatedForTheReacquireTimeThenItBecomesTheReference) {
  FieldGateParams p;  // reacquire after 20 s
  FieldGate g = learnt_gate(p, 50.0, 60.0);
  int k = 0;
  while (g.reacquired == 0 && k < 5000) {
    g.step(p, field(60.0, 60.0), kUp, kDt);
    g.tick(p, kDt);
    ++k;
  }
  EXPECT_EQ(g.reacquired, 1u);
  // adopted after reacquire_s of rejection (stable from the second gated sample)
  EXPECT_NEAR(k * kDt, p.reacquire_s + kDt, 2.0 * kDt);  // s
  EXPECT_NEAR(g.m_ut, 60.0, 0.01);                       // uT
  EXPECT_EQ(g.step(p, field(60.0, 60.0), kUp, kDt), FieldVerdict::kAccepted);
}

TEST(FieldGate, GivenAFieldThatNeverSettlesWhenGatedForTheMaxRejectTimeThenItIsUsedAnyway) {
  FieldGateParams p;
  p.reacquire_s = 0.0;
  p.max_reject_s = 5.0;
  FieldGate g = learnt_gate(p, 50.0, 60.0);
  int gated = 0;
  int forced = 0;
  for (int k = 0; k < 1000; ++k) {  // 10 s
    const FieldVerdict v = g.step(p, field(k % 2 == 0 ? 60.0 : 40.0, 60.0), kUp, kDt);
    gated += v == FieldVerdict::kGated ? 1 : 0;
    forced += v == FieldVerdict::kForced ? 1 : 0;
  }
  // 5 s of gating (500 samples; one more when the summed 0.01 s steps land just below 5 s), then forced
  EXPECT_NEAR(gated, 500, 1);
  EXPECT_EQ(forced, 1000 - gated);
  EXPECT_EQ(g.forced, static_cast<uint64_t>(forced));
}

TEST(FieldGate, GivenAConfiguredReferenceWhenResetThenNothingIsLearnt) {
  FieldGateParams p;
  p.field_magnitude_ut = 45.0;
  p.dip_deg = 55.0;
  FieldGate g;
  g.reset(p);
  EXPECT_TRUE(g.learnt);
  EXPECT_EQ(g.step(p, field(45.0, 55.0), kUp, kDt), FieldVerdict::kAccepted);
  EXPECT_EQ(g.step(p, field(50.0, 55.0), kUp, kDt), FieldVerdict::kGated);
}

// FieldGate::offset_removed (session 27): a reference learnt at start-up on a field with a
// body-fixed offset in it (a magnet on the sensor at power-on) is moved to the field without it
// once the filter removes the offset, and kept when the offset came later. Oracle: the Earth's
// field and the offset are the test's; the reference without the offset is the Earth field's own
// magnitude and dip, in closed form.
constexpr double kEarthUt = 44.0;
constexpr double kEarthDipDeg = 65.0;
constexpr double kRefTolUt = 1e-9;    // the reference is computed, not estimated: rounding, uT
constexpr double kRefTolDeg = 1e-7;   // deg
const Eigen::Vector3d kMagnetUt(-8.0, 6.0, 3.0);  // 10.4 uT, across the horizontal field

double dip_deg_of(const Eigen::Vector3d& f) { return std::asin(-kUp.dot(f) / f.norm()) * kDegPerRad; }

/// The gate's reference is the magnitude and dip of the field `f` (body, up +z).
void expect_reference(const FieldGate& g, const Eigen::Vector3d& f) {
  EXPECT_NEAR(g.m_ut, f.norm(), kRefTolUt);
  EXPECT_NEAR(g.dip_rad * kDegPerRad, dip_deg_of(f), kRefTolDeg);
}

/// A gate learnt on `startup` (body = the test's frame, up +z), then given `later` with `offset`
/// removed for `seconds`; the judgements returned in order of change.
std::vector<OffsetJudgement> judge(FieldGate& g, const FieldGateParams& p, const Eigen::Vector3d& startup,
                                   const Eigen::Vector3d& offset, const Eigen::Vector3d& later, double seconds) {
  g.reset(p);
  g.step(p, startup, kUp, 0.0);
  while (!g.learnt) {
    g.step(p, startup, kUp, kDt);
  }
  std::vector<OffsetJudgement> seen;
  for (double t = 0.0; t < seconds; t += kDt) {
    const OffsetJudgement j = g.offset_removed(p, offset, later, kUp, kDt);
    if (seen.empty() || seen.back() != j) {
      seen.push_back(j);
    }
  }
  return seen;
}

TEST(FieldGateOffset, GivenAMagnetOnTheSensorAtStartUpWhenItsOffsetIsRemovedThenTheReferenceIsTheEarthFieldsAndTheHeadingRestarts) {
  const FieldGateParams p;  // start-up 1 s, 5 % and 10 deg
  const Eigen::Vector3d earth = field(kEarthUt, kEarthDipDeg);
  FieldGate g;
  // GIVEN a start-up on the Earth's field plus the magnet's (learnt as a field of its own)
  // WHEN the filter removes the magnet's offset and the field left is the Earth's
  const auto seen = judge(g, p, earth + kMagnetUt, kMagnetUt, earth, 3.0);
  // THEN it is judged once, after one start-up span, and moved to the Earth field's magnitude and dip
  ASSERT_EQ(seen, (std::vector<OffsetJudgement>{OffsetJudgement::kOpen, OffsetJudgement::kMoved,
                                                OffsetJudgement::kNone}));
  expect_reference(g, earth);
  EXPECT_EQ(g.offset_moves, 1u);
  EXPECT_EQ(g.reference_epoch, 1u);  // what a filter derived from the reference starts again
  // the next sample restarts the heading on the field, and the field is accepted from then on
  EXPECT_EQ(g.step(p, earth, kUp, kDt), FieldVerdict::kRelearnt);
  EXPECT_EQ(g.step(p, earth, kUp, kDt), FieldVerdict::kAccepted);
  // AND when the filter stops removing the offset, the start-up's reference is back
  g.offset_not_removed();
  expect_reference(g, earth + kMagnetUt);
  EXPECT_EQ(g.reference_epoch, 2u);
  EXPECT_EQ(g.step(p, earth + kMagnetUt, kUp, kDt), FieldVerdict::kAccepted);
}

TEST(FieldGateOffset, GivenAStartUpWithoutTheMagnetWhenItsOffsetIsRemovedLaterThenTheReferenceStays) {
  const FieldGateParams p;
  const Eigen::Vector3d earth = field(kEarthUt, kEarthDipDeg);
  FieldGate g;
  // GIVEN a start-up on the Earth's field alone, WHEN a magnet's offset is removed later
  const auto seen = judge(g, p, earth, kMagnetUt, earth, 3.0);
  // THEN the learnt reference fits the field without it: kept, and not judged again
  ASSERT_EQ(seen, (std::vector<OffsetJudgement>{OffsetJudgement::kOpen, OffsetJudgement::kKept,
                                                OffsetJudgement::kNone}));
  expect_reference(g, earth);
  EXPECT_EQ(g.offset_moves, 0u);
  EXPECT_EQ(g.step(p, earth, kUp, kDt), FieldVerdict::kAccepted);
}

TEST(FieldGateOffset, GivenAFieldThatFitsNeitherReferenceWhenJudgedThenNothingMovesUntilOneFits) {
  const FieldGateParams p;
  const Eigen::Vector3d earth = field(kEarthUt, kEarthDipDeg);
  FieldGate g;
  // GIVEN a start-up with the magnet, WHEN the field without it is 20 % stronger than either
  // reference (an offset's estimate off, or another place's field)
  const auto seen = judge(g, p, earth + kMagnetUt, kMagnetUt, 1.2 * earth, 3.0);
  // THEN every span stays open and the reference is the start-up's
  ASSERT_EQ(seen, (std::vector<OffsetJudgement>{OffsetJudgement::kOpen}));
  EXPECT_NEAR(g.m_ut, (earth + kMagnetUt).norm(), kRefTolUt);
  // AND a span that fits the reference without the offset still moves it
  for (double t = 0.0; t < 1.5; t += kDt) {
    g.offset_removed(p, kMagnetUt, earth, kUp, kDt);
  }
  EXPECT_NEAR(g.m_ut, kEarthUt, kRefTolUt);
}

TEST(FieldGateOffset, GivenAFieldThatMovedAtRestOrAConfiguredReferenceThenNothingIsJudged) {
  const Eigen::Vector3d earth = field(kEarthUt, kEarthDipDeg);
  {
    const FieldGateParams p;
    FieldGate g;
    judge(g, p, earth + kMagnetUt, kMagnetUt, earth + kMagnetUt, 0.5);  // half a span
    g.offset_after_startup();  // e.g. the field moved at rest: the offset came later
    EXPECT_EQ(g.offset_removed(p, kMagnetUt, earth, kUp, kDt), OffsetJudgement::kNone);
    EXPECT_NEAR(g.m_ut, (earth + kMagnetUt).norm(), kRefTolUt);
  }
  {
    FieldGateParams p;  // the World Magnetic Model's reference: the Earth's, whatever the start-up saw
    p.field_magnitude_ut = 50.0;
    p.dip_deg = 60.0;
    FieldGate g;
    g.reset(p);
    for (double t = 0.0; t < 3.0; t += kDt) {
      EXPECT_EQ(g.offset_removed(p, kMagnetUt, earth, kUp, kDt), OffsetJudgement::kNone);
    }
    EXPECT_EQ(g.m_ut, 50.0);
  }
}

TEST(FieldGateOffset, GivenHostileInputsWhenJudgedThenNothingIsSummedAndTheReferenceStaysFinite) {
  const FieldGateParams p;
  const Eigen::Vector3d earth = field(kEarthUt, kEarthDipDeg);
  const double nan = std::nan("");
  const double inf = std::numeric_limits<double>::infinity();
  FieldGate g;
  judge(g, p, earth + kMagnetUt, kMagnetUt, earth, 0.5);  // half a span summed
  const double m_before = g.m_ut;
  for (int k = 0; k < 300; ++k) {  // 3 s of each
    EXPECT_EQ(g.offset_removed(p, Eigen::Vector3d(nan, 0.0, 0.0), earth, kUp, kDt), OffsetJudgement::kOpen);
    EXPECT_EQ(g.offset_removed(p, kMagnetUt, Eigen::Vector3d(inf, 1.0, 1.0), kUp, kDt), OffsetJudgement::kOpen);
    EXPECT_EQ(g.offset_removed(p, kMagnetUt, earth, Eigen::Vector3d::Zero(), kDt), OffsetJudgement::kOpen);
    EXPECT_EQ(g.offset_removed(p, kMagnetUt, earth, kUp, nan), OffsetJudgement::kOpen);
    EXPECT_EQ(g.offset_removed(p, kMagnetUt, earth, kUp, -kDt), OffsetJudgement::kOpen);
  }
  EXPECT_EQ(g.m_ut, m_before);
  // an offset of 1e308 uT: its reference is not finite, so the span stays open
  for (double t = 0.0; t < 3.0; t += kDt) {
    EXPECT_EQ(g.offset_removed(p, Eigen::Vector3d(1e308, 0.0, 0.0), earth, kUp, kDt), OffsetJudgement::kOpen);
  }
  EXPECT_EQ(g.m_ut, m_before);
  EXPECT_TRUE(std::isfinite(g.dip_rad));
}

// FieldMovedAtRest::hold (session 20): a field that moved at rest stays refused in the motion after
// it until the hard-iron estimate has judged it or the field is back at the rest's field. Oracle:
// the fields fed (the frame is the test's; the Earth's field fixed in it).
constexpr double kMovedTolUt = 2.2;     // the gate's norm tolerance, uT (0.05 x 44)
constexpr double kMovedLowpassS = 0.5;  // the rest detector's time constant, s
constexpr double kMovedSettleS = 5.0;   // ten low-pass time constants, s

/// Steps `fr` for `seconds` with the field `f` (held verdict of the last sample).
bool run_moved(FieldMovedAtRest& fr, const Eigen::Vector3d& f, bool rest, bool judged, double seconds) {
  bool held = false;
  for (double t = 0.0; t < seconds; t += kDt) {
    const bool moved = fr.step(f, rest, kDt, kMovedLowpassS, 0.0, kMovedTolUt);
    held = fr.hold(moved, rest, judged, kMovedTolUt);
  }
  return held;
}

TEST(FieldMovedAtRest, GivenAFieldThatMovedAtRestWhenTheMotionStartsThenItIsHeldUntilJudgedOrBack) {
  const Eigen::Vector3d earth(15.0, 0.0, -41.3);           // 44 uT at 70 deg dip
  const Eigen::Vector3d magnet = earth + Eigen::Vector3d(5.0, 0.0, 0.0);  // 5 uT more: moved
  // GIVEN a rest that began in the Earth's field, then a magnet's field
  FieldMovedAtRest fr;
  EXPECT_FALSE(run_moved(fr, earth, true, false, kMovedSettleS));
  EXPECT_TRUE(run_moved(fr, magnet, true, false, kMovedSettleS));
  // WHEN the motion starts with the magnet's field still there and nothing judged
  // THEN it stays held (the rest's field is kept)
  EXPECT_TRUE(run_moved(fr, magnet, false, false, kMovedSettleS));
  // and WHEN the field comes back to the rest's field THEN it is released
  FieldMovedAtRest back = fr;
  EXPECT_FALSE(run_moved(back, earth, false, false, kMovedSettleS));
  // and WHEN the hard-iron estimate has judged it THEN it is released at once
  FieldMovedAtRest judged = fr;
  EXPECT_FALSE(judged.hold(false, false, true, kMovedTolUt));
  // and a field that did not move at rest is never held in the motion
  FieldMovedAtRest clean;
  run_moved(clean, earth, true, false, kMovedSettleS);
  EXPECT_FALSE(run_moved(clean, magnet, false, false, kMovedSettleS));
}

}  // namespace
}  // namespace poise
