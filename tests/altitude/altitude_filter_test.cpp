// AltitudeFilter scenarios in simulated time: rest, constant climb, bad input, configuration.
#include "poise/altitude/altitude_filter.h"

#include "poise/testing/one_hostile_sample.h"
#include "poise/testing/param_errors.h"
#include "poise/testing/state_round_trip.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <vector>
#include <fstream>
#include <stdexcept>

namespace poise {
namespace {

constexpr double kG = IsaConstants::kG;
constexpr int64_t kStepNs = 10'000'000;  // 100 Hz
constexpr double kDt = 0.01;

/// A noiseless sample of a level, still or vertically moving sensor at height h.
/// `yaw_rate_rps` turns the sensor about the vertical (which keeps it level and the accelerometer
/// unchanged) so that the ZUPT detector does not take a constant-velocity climb for rest.
ImuSample level_sample(int64_t stamp_ns, double height_m, double vertical_accel_mps2 = 0.0,
                       double yaw_rate_rps = 0.0) {
  ImuSample s;
  s.stamp_ns = stamp_ns;
  s.accel_mps2 = Eigen::Vector3d(0.0, 0.0, kG + vertical_accel_mps2);
  s.gyro_rps = Eigen::Vector3d(0.0, 0.0, yaw_rate_rps);
  s.has_mag = false;
  s.has_pressure = true;
  s.pressure_pa = isa_pressure_pa(height_m, IsaConstants::kP0Pa);
  return s;
}

TEST(AltitudeFilter, GivenRestWhenRunThenHeightIsBaroAndVelocityZeroAndStationary) {
  constexpr double kHeightTolM = 1e-3;
  constexpr double kVelTolMps = 1e-6;
  AltitudeFilter f;
  for (int k = 0; k < 500; ++k) {
    ASSERT_TRUE(f.update(level_sample(k * kStepNs, 42.0)));
  }
  const auto& e = f.estimate();
  EXPECT_TRUE(e.valid);
  EXPECT_NEAR(e.height_m, 42.0, kHeightTolM);
  EXPECT_NEAR(e.baro_height_m, 42.0, kHeightTolM);
  EXPECT_NEAR(e.vertical_velocity_mps, 0.0, kVelTolMps);
  EXPECT_TRUE(e.stationary);
  EXPECT_TRUE(e.zupt_applied);
  EXPECT_EQ(f.rejects().total(), 0U);
}

/// GIVEN a constant 0.5 m/s climb (baro consistent, level, no noise) WHEN each method runs for 30 s
/// THEN the vertical velocity converges to 0.5 m/s and the height follows the truth.
class AltitudeMethodTest : public ::testing::TestWithParam<AltitudeMethod> {};

TEST_P(AltitudeMethodTest, ConstantClimbConverges) {
  constexpr double kClimbMps = 0.5;
  constexpr double kVelTolMps = 0.01;
  constexpr double kHeightTolM = 0.05;
  constexpr double kTurnRps = 0.3;
  AltitudeParams p;
  p.method = GetParam();
  AltitudeFilter f(p);
  // 2 s at rest, then accelerate at 0.5 m/s^2 for 1 s, then climb at constant speed.
  double h = 10.0;
  double v = 0.0;
  int64_t t = 0;
  for (int k = 0; k < 3200; ++k) {
    const double a = (k >= 200 && k < 300) ? kClimbMps : 0.0;
    ASSERT_TRUE(f.update(level_sample(t, h, a, kTurnRps)));
    h += v * kDt + 0.5 * a * kDt * kDt;
    v += a * kDt;
    t += kStepNs;
  }
  EXPECT_NEAR(v, kClimbMps, 1e-9);
  EXPECT_NEAR(f.estimate().vertical_velocity_mps, kClimbMps, kVelTolMps) << to_string(p.method);
  EXPECT_NEAR(f.estimate().height_m, h, kHeightTolM) << to_string(p.method);
  EXPECT_FALSE(f.estimate().stationary);
}

INSTANTIATE_TEST_SUITE_P(AllMethods, AltitudeMethodTest,
                         ::testing::Values(AltitudeMethod::kTwoStepKf, AltitudeMethod::kCfZupt,
                                           AltitudeMethod::kPiCfZupt, AltitudeMethod::kPiCf));

TEST(AltitudeFilter, GivenAccelBiasWhenMovingWithoutStopsThenTheIntegralShrinksTheVelocityError) {
  // GIVEN a 0.05 m/s^2 vertical accelerometer bias b and a constant 0.3 m/s climb (no stop: ZUPT
  // cannot help) WHEN 300 s pass THEN the steady-state velocity errors are those of the loops:
  //   conventional CF (13):          k1 b / k2      (0.19 m/s with the default gains)
  //   PI CF, K_i [1; 1] (default):   b * 1 s        (the integral also feeds the height rate)
  //   PI CF, K_i [0; 1]:             0
  constexpr double kBias = 0.05;
  constexpr double kClimbMps = 0.3;
  constexpr double kTurnRps = 0.3;
  constexpr double kRelTol = 0.1;
  constexpr double kZeroTolMps = 0.005;
  auto run = [&](AltitudeMethod m, bool velocity_only) {
    AltitudeParams p;
    p.method = m;
    p.integral_velocity_only = velocity_only;
    AltitudeFilter f(p);
    double h = 0.0;
    for (int k = 0; k < 30000; ++k) {
      f.update(level_sample(k * kStepNs, h, kBias, kTurnRps));
      h += kClimbMps * kDt;
    }
    return std::make_pair(f.estimate().vertical_velocity_mps - kClimbMps, f.cf_gain());
  };
  const auto [err_cf, gain] = run(AltitudeMethod::kCfZupt, false);
  const double expected_cf = gain(0) * kBias / gain(1);
  EXPECT_NEAR(err_cf, expected_cf, kRelTol * expected_cf);
  const double err_pi = run(AltitudeMethod::kPiCfZupt, false).first;
  EXPECT_NEAR(err_pi, kBias * 1.0, kRelTol * kBias);
  EXPECT_LT(std::abs(err_pi), 0.5 * std::abs(err_cf));
  const double err_pi_v = run(AltitudeMethod::kPiCfZupt, true).first;
  EXPECT_LT(std::abs(err_pi_v), kZeroTolMps);
}

TEST(AltitudeFilter, GivenBaroAt25HzThenHeldValueKeepsTheLoopAndAStaleBaroIsNotUsed) {
  // GIVEN the barometer in every 4th sample (25 Hz) and a 0.5 m/s climb WHEN the filter runs THEN
  // it converges as at 100 Hz (the last baro height is held between samples).
  constexpr double kClimbMps = 0.5;
  constexpr double kTurnRps = 0.3;
  AltitudeFilter f;
  double h = 0.0;
  double v = 0.0;
  int64_t t = 0;
  for (int k = 0; k < 3200; ++k, t += kStepNs) {
    const double a = (k >= 200 && k < 300) ? kClimbMps : 0.0;  // 2 s still, then 1 s at 0.5 m/s^2
    ImuSample s = level_sample(t, h, a, kTurnRps);
    s.has_pressure = k % 4 == 0;
    ASSERT_TRUE(f.update(s));
    EXPECT_EQ(f.estimate().baro_fresh, s.has_pressure);
    h += v * kDt + 0.5 * a * kDt * kDt;
    v += a * kDt;
  }
  EXPECT_NEAR(f.estimate().vertical_velocity_mps, kClimbMps, 0.01);
  EXPECT_NEAR(f.estimate().height_m, h, 0.05);
  // WHEN the barometer stops for 5 s THEN no correction uses the stale height: the integral
  // (which only grows with fresh innovations) is frozen.
  const double integral_before = f.estimate().integral_sum_m;
  for (int k = 0; k < 500; ++k, t += kStepNs) {
    ImuSample s = level_sample(t, h, 0.0, kTurnRps);
    s.has_pressure = false;
    ASSERT_TRUE(f.update(s));
  }
  // Within max_baro_age_s (0.5 s) the held value still counts; after it nothing changes.
  const double integral_mid = f.estimate().integral_sum_m;
  for (int k = 0; k < 100; ++k, t += kStepNs) {
    ImuSample s = level_sample(t, h, 0.0, kTurnRps);
    s.has_pressure = false;
    ASSERT_TRUE(f.update(s));
  }
  EXPECT_NE(integral_before, integral_mid);
  EXPECT_DOUBLE_EQ(f.estimate().integral_sum_m, integral_mid);
}

TEST(AltitudeFilter, GainsFollowEquation14OrHiggins) {
  AltitudeParams p;
  p.sigma_acc_mps2 = 0.08;
  p.sigma_baro_m = 0.5;
  p.gains = CfGains::kPaper;
  AltitudeFilter paper(p);
  EXPECT_NEAR(paper.cf_gain()(0), std::sqrt(0.16), 1e-12);
  EXPECT_NEAR(paper.cf_gain()(1), 0.16, 1e-12);
  p.gains = CfGains::kHiggins;
  AltitudeFilter higgins(p);
  EXPECT_NEAR(higgins.cf_gain()(0), std::sqrt(0.32), 1e-12);
  EXPECT_NEAR(higgins.cf_gain()(1), 0.16, 1e-12);
}

TEST(AltitudeFilter, BadInputIsRejectedAndCounted) {
  AltitudeFilter f;
  int64_t t = 0;
  for (int k = 0; k < 100; ++k, t += kStepNs) {
    ASSERT_TRUE(f.update(level_sample(t, 5.0)));
  }
  const double h_before = f.estimate().height_m;

  // WHEN pressures <= 0, NaN and out of range arrive THEN only the pressure is rejected.
  for (double bad : {0.0, -100.0, std::nan(""), 5000.0, 200000.0}) {
    ImuSample s = level_sample(t, 5.0);
    s.pressure_pa = bad;
    EXPECT_TRUE(f.update(s));
    EXPECT_FALSE(f.estimate().baro_fresh);
    t += kStepNs;
  }
  EXPECT_EQ(f.rejects().count(RejectReason::kPressureOutOfRange), 4U);
  EXPECT_EQ(f.rejects().count(RejectReason::kNonFinitePressure), 1U);

  // WHEN the accelerometer or gyro is NaN or missing THEN the sample is rejected.
  ImuSample nan_accel = level_sample(t, 5.0);
  nan_accel.accel_mps2.x() = std::nan("");
  EXPECT_FALSE(f.update(nan_accel));
  ImuSample inf_gyro = level_sample(t, 5.0);
  inf_gyro.gyro_rps.z() = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(f.update(inf_gyro));
  ImuSample no_accel = level_sample(t, 5.0);
  no_accel.has_accel = false;
  EXPECT_FALSE(f.update(no_accel));
  EXPECT_EQ(f.rejects().count(RejectReason::kNonFiniteAccel), 1U);
  EXPECT_EQ(f.rejects().count(RejectReason::kNonFiniteGyro), 1U);
  EXPECT_EQ(f.rejects().count(RejectReason::kMissingAccel), 1U);

  // WHEN a stamp repeats or goes back THEN it is rejected.
  EXPECT_FALSE(f.update(level_sample(t - kStepNs, 5.0)));
  EXPECT_FALSE(f.update(level_sample(t - 10 * kStepNs, 5.0)));
  EXPECT_EQ(f.rejects().count(RejectReason::kNonMonotonicStamp), 2U);

  // WHEN a 5 s gap arrives THEN the first two samples after it are refused (counted) and time
  // re-anchors at the second, which agrees with the first (StampAnchor); the filter keeps running.
  t += 500 * kStepNs;
  EXPECT_FALSE(f.update(level_sample(t, 5.0)));
  t += kStepNs;
  EXPECT_FALSE(f.update(level_sample(t, 5.0)));
  EXPECT_EQ(f.rejects().count(RejectReason::kTimeGap), 2U);
  for (int k = 0; k < 50; ++k) {
    t += kStepNs;
    ASSERT_TRUE(f.update(level_sample(t, 5.0)));
  }
  EXPECT_TRUE(std::isfinite(f.estimate().height_m));
  EXPECT_NEAR(f.estimate().height_m, h_before, 0.01);
  EXPECT_EQ(f.rejects().total(), 12U);
}

// Issue 19: one hostile sample between valid ones (a finite but impossible value, NaN, a stamp
// outside [0, 2^62] ns, a stamp back in time, one far in the future) is refused by the shared
// sample check, counted exactly once under its reason, and leaves the state untouched: the
// output afterwards is that of a filter that never saw it. A bad pressure refuses only the
// pressure: the oracle is then a filter that got the same sample without a pressure.
TEST(AltitudeFilter, GivenOneHostileSampleThenItIsCountedOnceAndTheOutputIsThatOfAFilterThatNeverSawIt) {
  constexpr double kSameAsCleanM = 1e-9;     // m (and m/s): the state is untouched, so equal
  constexpr int kHostileAt = 300;            // inserted between samples 299 and 300
  constexpr int kSamples = 600;
  // A vertical oscillation, 1 m at 0.2 Hz, turning slowly so that rest is never detected.
  const double w = 2.0 * 3.14159265358979323846 * 0.2;
  const auto sample = [w](int k) {
    const double t = k * kDt;
    return level_sample(k * kStepNs, 10.0 + std::sin(w * t), -w * w * std::sin(w * t), 0.3);
  };
  struct Case {
    const char* name;
    std::function<void(ImuSample&)> spoil;
    RejectReason reason;
    bool whole_sample;  // false: only the pressure is refused
  };
  const std::vector<Case> cases = {
      {"accel 1e308", [](ImuSample& s) { s.accel_mps2.z() = 1e308; }, RejectReason::kAccelOutOfRange, true},
      {"gyro 1e308", [](ImuSample& s) { s.gyro_rps.x() = 1e308; }, RejectReason::kGyroOutOfRange, true},
      {"accel NaN", [](ImuSample& s) { s.accel_mps2.x() = std::nan(""); }, RejectReason::kNonFiniteAccel, true},
      {"stamp INT64_MAX", [](ImuSample& s) { s.stamp_ns = std::numeric_limits<int64_t>::max(); },
       RejectReason::kStampOutOfRange, true},
      {"stamp INT64_MIN", [](ImuSample& s) { s.stamp_ns = std::numeric_limits<int64_t>::min(); },
       RejectReason::kStampOutOfRange, true},
      {"stamp -1 ns", [](ImuSample& s) { s.stamp_ns = -1; }, RejectReason::kStampOutOfRange, true},
      {"stamp back 10 ms", [](ImuSample& s) { s.stamp_ns -= kStepNs; }, RejectReason::kNonMonotonicStamp, true},
      {"stamp +1e15 ns", [](ImuSample& s) { s.stamp_ns += 1'000'000'000'000'000; }, RejectReason::kTimeGap, true},
      {"pressure NaN", [](ImuSample& s) { s.pressure_pa = std::nan(""); }, RejectReason::kNonFinitePressure, false},
      {"pressure 1e308 Pa", [](ImuSample& s) { s.pressure_pa = 1e308; }, RejectReason::kPressureOutOfRange, false},
      {"pressure 0 Pa", [](ImuSample& s) { s.pressure_pa = 0.0; }, RejectReason::kPressureOutOfRange, false},
  };
  for (const Case& c : cases) {
    AltitudeFilter f;
    AltitudeFilter clean;
    const bool used = testing::run_with_one_hostile_sample(
        f, clean, kSamples, kHostileAt, kStepNs / 2, c.whole_sample, sample, c.spoil,
        [](ImuSample& s) { s.has_pressure = false; });
    EXPECT_EQ(used, !c.whole_sample) << c.name;
    EXPECT_EQ(f.rejects().count(c.reason), 1u) << c.name;
    EXPECT_EQ(f.rejects().total(), 1u) << c.name;
    EXPECT_EQ(f.state_resets(), 0u) << c.name;
    ASSERT_TRUE(f.estimate().valid) << c.name;
    EXPECT_NEAR(f.estimate().height_m, clean.estimate().height_m, kSameAsCleanM) << c.name;
    EXPECT_NEAR(f.estimate().vertical_velocity_mps, clean.estimate().vertical_velocity_mps, kSameAsCleanM) << c.name;
    // and the clean filter tracks the truth (so the comparison is of a working filter)
    EXPECT_NEAR(clean.estimate().height_m, 10.0 + std::sin(w * (kSamples - 1) * kDt), 0.1) << c.name;
  }
}

TEST(AltitudeFilter, InvalidParamsThrow) {
  AltitudeParams p;
  p.sigma_baro_m = 0.0;
  EXPECT_THROW(AltitudeFilter{p}, std::invalid_argument);
  p = AltitudeParams{};
  p.min_pressure_pa = 120000.0;
  EXPECT_THROW(p.validate(), std::invalid_argument);
}

// Defaults in one place: the shipped file holds only what differs from AltitudeParams{} (nothing),
// so loading it gives exactly the struct, every field compared (a rounded copy of a default, e.g.
// 0.000873 for 0.05 deg/s, fails here).
TEST(AltitudeConfig, ShippedYamlIsExactlyTheDefaultsFieldByField) {
  const AltitudeParams p = load_altitude_params(testing::source_path("config/filters/altitude.yaml"));
  const AltitudeParams d;
  EXPECT_EQ(p.method, d.method);
  EXPECT_EQ(p.gravity_mps2, d.gravity_mps2);
  EXPECT_EQ(p.reference_pressure_pa, d.reference_pressure_pa);
  EXPECT_EQ(p.paper_rounded_constants, d.paper_rounded_constants);
  EXPECT_EQ(p.min_pressure_pa, d.min_pressure_pa);
  EXPECT_EQ(p.max_pressure_pa, d.max_pressure_pa);
  EXPECT_EQ(p.max_baro_age_s, d.max_baro_age_s);
  EXPECT_EQ(p.gains, d.gains);
  EXPECT_EQ(p.sigma_acc_mps2, d.sigma_acc_mps2);
  EXPECT_EQ(p.sigma_baro_m, d.sigma_baro_m);
  EXPECT_EQ(p.k_i, d.k_i);
  EXPECT_EQ(p.integral_velocity_only, d.integral_velocity_only);
  EXPECT_EQ(p.integral_time_scaled, d.integral_time_scaled);
  EXPECT_EQ(p.zupt_gyro_max_rps, d.zupt_gyro_max_rps);
  EXPECT_EQ(p.zupt_accel_dev_max_mps2, d.zupt_accel_dev_max_mps2);
  EXPECT_EQ(p.zupt_window_s, d.zupt_window_s);
  EXPECT_EQ(p.max_dt_s, d.max_dt_s);
  EXPECT_EQ(p.max_gyro_rps, d.max_gyro_rps);
  EXPECT_EQ(p.max_accel_mps2, d.max_accel_mps2);
  EXPECT_EQ(p.tilt.sigma_gyro_rps, d.tilt.sigma_gyro_rps);
  EXPECT_EQ(p.tilt.sigma_accel_mps2, d.tilt.sigma_accel_mps2);
  EXPECT_EQ(p.tilt.c_a, d.tilt.c_a);
  EXPECT_EQ(p.tilt.c_a_rate_hz, d.tilt.c_a_rate_hz);
  EXPECT_EQ(p.tilt.gravity_mps2, d.tilt.gravity_mps2);
  EXPECT_EQ(p.tilt.exact_rotation, d.tilt.exact_rotation);
  EXPECT_EQ(p.tilt.renormalize, d.tilt.renormalize);
  EXPECT_EQ(p.tilt.sigma_gyro_extra_rps, d.tilt.sigma_gyro_extra_rps);
  EXPECT_EQ(p.tilt.initial_var_tilt, d.tilt.initial_var_tilt);
  EXPECT_EQ(p.tilt.initial_var_accel, d.tilt.initial_var_accel);
}

TEST(AltitudeConfig, UnknownKeysAndBadValuesAreErrors) {
  const std::string path = ::testing::TempDir() + "/altitude_bad.yaml";
  const auto write = [&path](const std::string& text) {
    std::ofstream(path) << text;
  };
  write("cf:\n  sigma_acc: 0.1\n");
  EXPECT_THROW(load_altitude_params(path), std::runtime_error);
  write("method: magic\n");
  EXPECT_THROW(load_altitude_params(path), std::runtime_error);
  write("cf:\n  sigma_baro_m: -1\n");
  EXPECT_THROW(load_altitude_params(path), std::runtime_error);
  write("barometer:\n  reference_pressure_pa: 102000\nmethod: cf_zupt\n");
  const AltitudeParams p = load_altitude_params(path);
  EXPECT_DOUBLE_EQ(p.reference_pressure_pa, 102000.0);
  EXPECT_EQ(p.method, AltitudeMethod::kCfZupt);
  EXPECT_THROW(load_altitude_params(path + ".missing"), std::runtime_error);
}

TEST(StartZero, GivenBaroHeightsWhenTheFirstSecondHasPassedThenTheZeroIsTheirMean) {
  // GIVEN estimates every 10 ms with a fresh baro height on every other one: 100 m +/- 0.3 m
  StartZero zero;
  AltitudeEstimate e;
  e.valid = true;
  double sum = 0.0;
  int n = 0;
  std::optional<double> z;
  for (int k = 0; k <= 150; ++k) {
    e.stamp_ns = 5'000'000'000 + int64_t{k} * 10'000'000;
    e.baro_fresh = k % 2 == 0;
    e.baro_height_m = 100.0 + ((k / 2) % 2 == 0 ? 0.3 : -0.3);
    const bool before_window_end = e.stamp_ns - 5'000'000'000 < 1'000'000'000;
    if (e.baro_fresh && before_window_end) {
      sum += e.baro_height_m;
      ++n;
    } else if (e.baro_fresh && !z) {
      sum += e.baro_height_m;  // the sample that closes the window counts too
      ++n;
    }
    z = zero.add(e);
    // THEN nothing before 1 s, the mean of the window's heights from then on (fixed)
    if (before_window_end) {
      ASSERT_FALSE(z.has_value()) << k;
    } else {
      ASSERT_TRUE(z.has_value()) << k;
      EXPECT_NEAR(*z, sum / n, 1e-12);
    }
  }
  EXPECT_NEAR(*z, 100.0, 0.02);
}

TEST(StartZero, GivenNoBaroOrInvalidEstimatesThenNoZeroYet) {
  StartZero zero;
  AltitudeEstimate e;
  e.valid = false;  // filter not initialised: ignored
  e.baro_fresh = true;
  e.baro_height_m = 50.0;
  e.stamp_ns = 0;
  EXPECT_FALSE(zero.add(e).has_value());
  e.valid = true;
  e.baro_fresh = false;  // valid but no barometer for 2 s: the zero waits for one
  for (int k = 0; k < 200; ++k) {
    e.stamp_ns = int64_t{k} * 10'000'000;
    EXPECT_FALSE(zero.add(e).has_value());
  }
  e.baro_fresh = true;
  e.stamp_ns = 2'000'000'000;
  ASSERT_TRUE(zero.add(e).has_value());
  EXPECT_DOUBLE_EQ(*zero.zero(), 50.0);
}

// The baro source: fused with its innovation eps (15), rejected when bad, not available without.
TEST(AltitudeSources, BaroDecisionsAndInnovation) {
  AltitudeFilter f;
  ImuSample s;
  s.accel_mps2 = Eigen::Vector3d(0, 0, 9.80665);
  s.has_pressure = true;
  s.pressure_pa = 100000.0;
  for (int i = 0; i < 10; ++i) {
    s.stamp_ns = 1'000'000'000 + i * 10'000'000;
    ASSERT_TRUE(f.update(s));
  }
  SourceReports r = f.sources();
  ASSERT_EQ(r.size(), 4U);
  EXPECT_EQ(r[2].source, Source::kBaro);
  EXPECT_EQ(r[2].decision, SourceDecision::kFused);
  ASSERT_EQ(r[2].innovation.size(), 1);
  EXPECT_NEAR(r[2].innovation[0], f.estimate().baro_height_m - f.estimate().height_m, 1e-12);
  s.stamp_ns += 10'000'000;
  s.pressure_pa = -1.0;
  ASSERT_TRUE(f.update(s));
  EXPECT_EQ(f.sources()[2].decision, SourceDecision::kRejected);
  EXPECT_STREQ(f.sources()[2].reason, "pressure_out_of_range");
  s.stamp_ns += 10'000'000;
  s.has_pressure = false;
  ASSERT_TRUE(f.update(s));
  EXPECT_EQ(f.sources()[2].decision, SourceDecision::kNotAvailable);
  s.stamp_ns -= 5'000'000;  // back in time: the whole sample is rejected
  EXPECT_FALSE(f.update(s));
  for (const SourceReport& src : f.sources()) {
    EXPECT_EQ(src.decision, SourceDecision::kRejected) << to_string(src.source);
    EXPECT_STREQ(src.reason, "non_monotonic_stamp");
  }
}

std::string fingerprint(const AltitudeFilter& f) {
  const AltitudeEstimate& e = f.estimate();
  testing::Fingerprint p;
  p.add(e.stamp_ns).add(e.height_m).add(e.vertical_velocity_mps).add(e.vertical_accel_mps2).add(e.baro_height_m);
  p.add(e.baro_fresh).add(e.stationary).add(e.zupt_applied).add(e.integral_sum_m).add(e.valid);
  p.add(f.kf_covariance()).add(f.tilt().up_body()).add(f.sources()).add(f.rejects()).add(f.state_resets());
  return p.str();
}

TEST(AltitudeFilter, GivenAStateTakenMidRunWhenRestoredThenTheSameSamplesGiveBitIdenticalOutputsAndReports) {
  // GIVEN a filter 3 s into a 0.2 Hz vertical oscillation (+-1 m), level, turning slowly
  constexpr double kOmega = 2.0 * kPi * 0.2;
  const auto sample = [&](int k) {
    const double t = k * kDt;
    return level_sample(k * kStepNs, std::sin(kOmega * t), -kOmega * kOmega * std::sin(kOmega * t), 0.3);
  };
  AltitudeFilter a;
  int k = 0;
  for (; k < 300; ++k) {
    ASSERT_TRUE(a.update(sample(k)));
  }
  std::vector<ImuSample> next;  // the next 20 s, one pressure refused
  for (; k < 2300; ++k) {
    next.push_back(sample(k));
  }
  next[500].pressure_pa = std::nan("");
  // WHEN they run, then run again from the state taken before them (in a new filter and in the
  // same one) and after reset() next to a new filter, THEN every output, report and counter is the
  // same bit for bit: state() holds everything
  testing::expect_state_round_trips(a, next, [] { return AltitudeFilter(); }, fingerprint);
}

// One validation shape (ParamCheck): a bad value of a key is an error at construction that names
// the key as in the YAML file and its range/unit, never a silent repair or a NaN later.
TEST(AltitudeParams, GivenABadValueOfAKeyWhenTheFilterIsBuiltThenTheErrorNamesTheKey) {
  testing::expect_bad_values_name_their_keys<AltitudeParams>("altitude", AltitudeParams{}, {
    {"cf.sigma_baro_m", [](AltitudeParams& p) { p.sigma_baro_m = 0.0; }},
    {"barometer.min_pressure_pa", [](AltitudeParams& p) { p.min_pressure_pa = 120000.0; }},
    {"zupt.window_s", [](AltitudeParams& p) { p.zupt_window_s = std::nan(""); }},
    {"tilt.c_a", [](AltitudeParams& p) { p.tilt.c_a = -0.1; }}
  }, [](const AltitudeParams& p) { AltitudeFilter f(p); });
}

}  // namespace
}  // namespace poise

namespace poise {
namespace {

// State health (issue 19): a non-finite state or a covariance with a negative variance (through
// set_state(): no sample that passes the input checks gets there) resets the filter on the next
// update, counted, nothing non-finite comes out, and it re-converges. Oracle: the true height.
TEST(AltitudeFilter, GivenAnUnhealthyStateWhenUpdatedThenTheFilterResetsCountsItAndReconverges) {
  constexpr double kHeightTolM = 1e-3;  // noiseless rest, 5 s after the reset
  constexpr double kHeightM = 42.0;
  struct Case {
    const char* name;
    AltitudeMethod method;
    void (*spoil)(AltitudeFilterState&);
  };
  const Case cases[] = {
      {"NaN height", AltitudeMethod::kPiCfZupt, [](AltitudeFilterState& st) { st.x(0) = std::nan(""); }},
      {"NaN tilt", AltitudeMethod::kPiCfZupt,
       [](AltitudeFilterState& st) { st.tilt.core().set_u(Eigen::Vector3d::Constant(std::nan(""))); }},
      {"negative height variance", AltitudeMethod::kTwoStepKf, [](AltitudeFilterState& st) { st.p_kf(0, 0) = -1.0; }},
  };
  for (const Case& c : cases) {
    AltitudeParams p;
    p.method = c.method;
    AltitudeFilter f(p);
    for (int k = 0; k < 1000; ++k) {
      if (k == 500) {
        AltitudeFilterState st = f.state();
        c.spoil(st);
        f.set_state(st);
        EXPECT_FALSE(f.update(level_sample(k * kStepNs, kHeightM))) << c.name;  // the resetting update
        EXPECT_FALSE(f.estimate().valid) << c.name;
        EXPECT_STREQ(f.sources()[0].reason, kStateResetReason) << c.name;
        continue;
      }
      f.update(level_sample(k * kStepNs, kHeightM));
      ASSERT_TRUE(std::isfinite(f.estimate().height_m) || !f.estimate().valid) << c.name << " at " << k;
    }
    EXPECT_EQ(f.state_resets(), 1u) << c.name;
    EXPECT_EQ(f.rejects().total(), 0u) << c.name;
    EXPECT_TRUE(f.estimate().valid) << c.name;
    EXPECT_NEAR(f.estimate().height_m, kHeightM, kHeightTolM) << c.name;
  }
}

}  // namespace
}  // namespace poise
