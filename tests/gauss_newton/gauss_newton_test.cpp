// Gauss-Newton orientation: closed-form oracles and a simulated magnet scenario.
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/core/consistency.h"

#include "poise/sim/sensor_simulator.h"

#include "poise/testing/param_errors.h"
#include "poise/testing/state_round_trip.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <limits>

#include <random>
#include <string>
#include <vector>

namespace poise {
namespace {

constexpr uint32_t kSeed = 99;
constexpr double kExactTolDeg = 1e-5;  // noise-free solution, deg
constexpr double kDipDeg = 60.0;

Eigen::Vector3d field_world() {
  const double d = kDipDeg * kRadPerDeg;
  return 50.0 * Eigen::Vector3d(0.0, std::cos(d), -std::sin(d));
}

TEST(GaussNewton, GivenExactVectorsWhenSolvedFromFarStartThenTruthIsRecovered) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  std::mt19937 rng(kSeed);
  std::uniform_real_distribution<double> ang(-1.2, 1.2);
  GaussNewtonParams p;
  p.max_iterations = 20;
  const GaussNewton gn(p);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Quaterniond q = quat_from_euler_zyx(ang(rng), ang(rng), 2.5 * ang(rng));
    const Eigen::Vector3d a = q.conjugate() * Eigen::Vector3d(0, 0, 9.81);
    const Eigen::Vector3d m = q.conjugate() * field_world();
    const Eigen::Quaterniond start = q * quat_exp(Eigen::Vector3d(0.3, -0.2, 0.4));  // 30 deg off
    const GaussNewtonResult r = gn.solve(a, m, start, kDipDeg * kRadPerDeg);
    EXPECT_LT(quat_angle_between(r.q_world_body, q) * kDegPerRad, kExactTolDeg);
    EXPECT_LT(r.residual, 1e-9);
    EXPECT_GE(r.iterations, 1);
    EXPECT_LE(r.iterations, p.max_iterations);
  }
}

TEST(GaussNewton, GivenStaticSensorWithMagnetWhenUpdatedThenHeadingIsCorruptedButRecovers) {
  // GIVEN the static_magnet scenario (the baseline has no disturbance compensation)
  sim::SensorSimulator sim(sim::make_scenario("static_magnet", 100.0, 4));
  GaussNewton gn;
  double sq_clean = 0.0;
  int n_clean = 0;
  double err_disturbed_deg = 0.0;
  // WHEN every sample is processed
  while (!sim.done()) {
    const sim::SimSample s = sim.next();
    ASSERT_TRUE(gn.update(s.imu));
    const double err = quat_angle_between(gn.result().q_world_body, s.truth.q_world_body) * kDegPerRad;
    if (s.truth.t_s > 5.0 && s.truth.t_s < 14.0) {
      sq_clean += err * err;
      ++n_clean;
    }
    if (s.truth.t_s > 20.0 && s.truth.t_s < 30.0) {
      err_disturbed_deg = std::max(err_disturbed_deg, err);
    }
  }
  // THEN it is accurate without disturbance and clearly wrong with the magnet near
  EXPECT_LT(std::sqrt(sq_clean / n_clean), 1.0);  // deg RMS (per-sample noise, no filtering)
  EXPECT_GT(err_disturbed_deg, 10.0);
  EXPECT_NEAR(gn.dip_rad() * kDegPerRad, 60.0, 0.5);
}

TEST(GaussNewton, BadInputIsRejectedAndCounted) {
  GaussNewton gn;
  ImuSample s;
  s.stamp_ns = 1000;
  s.accel_mps2 = Eigen::Vector3d(0, 0, 9.81);
  s.mag_ut = field_world();
  s.has_mag = true;
  ASSERT_TRUE(gn.update(s));
  const Eigen::Quaterniond before = gn.result().q_world_body;
  ImuSample bad = s;
  bad.stamp_ns = 2000;
  bad.accel_mps2.x() = std::nan("");
  EXPECT_FALSE(gn.update(bad));
  bad = s;
  bad.stamp_ns = 3000;
  bad.mag_ut.setZero();
  EXPECT_FALSE(gn.update(bad));
  bad = s;  // same stamp: non-monotonic
  EXPECT_FALSE(gn.update(bad));
  EXPECT_EQ(gn.result().q_world_body.coeffs(), before.coeffs());
  EXPECT_EQ(gn.rejections().count(RejectReason::kNonFiniteAccel), 1u);
  EXPECT_EQ(gn.rejections().count(RejectReason::kZeroMag), 1u);
  EXPECT_EQ(gn.rejections().count(RejectReason::kNonMonotonicStamp), 1u);
}

TEST(GaussNewton, ShippedConfigLoadsAndBadConfigIsRejected) {
  // Defaults in one place: the shipped file is exactly GaussNewtonParams{}, field by field.
  const GaussNewtonParams p =
      load_gauss_newton_params(std::string(POISE_SOURCE_DIR) + "/config/filters/gauss_newton.yaml");
  const GaussNewtonParams d;
  EXPECT_EQ(p.max_iterations, d.max_iterations);
  EXPECT_EQ(p.tolerance_rad, d.tolerance_rad);
  EXPECT_EQ(p.mag_weight, d.mag_weight);
  EXPECT_EQ(std::isnan(p.dip_deg), std::isnan(d.dip_deg));
  EXPECT_EQ(p.startup_samples, d.startup_samples);
  EXPECT_EQ(p.limits.min_accel_norm_mps2, d.limits.min_accel_norm_mps2);
  EXPECT_EQ(p.limits.min_mag_norm_ut, d.limits.min_mag_norm_ut);
  EXPECT_EQ(p.limits.max_dt_s, d.limits.max_dt_s);
  EXPECT_THROW(load_gauss_newton_params("/nonexistent.yaml"), std::runtime_error);
}

std::string fingerprint(const GaussNewton& gn) {
  const GaussNewtonResult& r = gn.result();
  testing::Fingerprint p;
  p.add(r.q_world_body.coeffs()).add(static_cast<int64_t>(r.iterations)).add(r.residual).add(gn.initialized());
  p.add(gn.dip_rad()).add(gn.sources()).add(gn.rejections()).add(gn.state_resets());
  return p.str();
}

TEST(GaussNewton, GivenAStateTakenMidRunWhenRestoredThenTheSameSamplesGiveBitIdenticalOutputsAndReports) {
  // GIVEN a filter 30 samples into the static_magnet scenario (dip still being learnt: 50 samples)
  sim::SensorSimulator sim(sim::make_scenario("static_magnet", 100.0, 3));
  GaussNewton a;
  for (int k = 0; k < 30; ++k) {
    ASSERT_TRUE(a.update(sim.next().imu));
  }
  std::vector<ImuSample> next;  // the next 20 s, one sample refused
  for (int k = 0; k < 2000; ++k) {
    next.push_back(sim.next().imu);
  }
  next[500].accel_mps2.x() = std::nan("");
  // WHEN they run, then run again from the state taken before them (in a new filter and in the
  // same one) and after reset() next to a new filter, THEN every output, report and counter is the
  // same bit for bit: state() holds everything
  testing::expect_state_round_trips(a, next, [] { return GaussNewton(); }, fingerprint);
}

// One validation shape (ParamCheck): a bad value of a key is an error at construction that names
// the key as in the YAML file and its range/unit, never a silent repair or a NaN later.
TEST(GaussNewtonParams, GivenABadValueOfAKeyWhenTheFilterIsBuiltThenTheErrorNamesTheKey) {
  testing::expect_bad_values_name_their_keys<GaussNewtonParams>("gauss_newton", GaussNewtonParams{}, {
    {"max_iterations", [](GaussNewtonParams& p) { p.max_iterations = 0; }},
    {"mag_weight", [](GaussNewtonParams& p) { p.mag_weight = -1.0; }},
    {"dip_deg", [](GaussNewtonParams& p) { p.dip_deg = 91.0; }},
    {"field_magnitude_ut", [](GaussNewtonParams& p) { p.field_magnitude_ut = -1.0; }},
    {"field_verify_s", [](GaussNewtonParams& p) { p.field_verify_s = -1.0; }},
    {"limits.max_gyro_rps", [](GaussNewtonParams& p) { p.limits.max_gyro_rps = std::numeric_limits<double>::infinity(); }}
  }, [](const GaussNewtonParams& p) { GaussNewton f(p); });
}

}  // namespace
}  // namespace poise

namespace poise {
namespace {

// State health (issue 19): a non-finite dip (through set_state(): no sample that passes the input
// checks gets there) resets the filter on the next update, counted, nothing non-finite comes out,
// and it re-converges. (A non-finite previous solution needs no reset: solve() starts from the
// identity then.) Oracle: a filter that was never spoilt.
TEST(GaussNewton, GivenAnUnhealthyStateWhenUpdatedThenTheFilterResetsCountsItAndReconverges) {
  constexpr double kSameAsCleanDeg = 0.5;  // dip learnt from other samples after the reset, deg
  struct Case {
    const char* name;
    void (*spoil)(GaussNewtonState&);
  };
  const Case cases[] = {
      {"NaN dip", [](GaussNewtonState& st) { st.dip_rad = std::nan(""); }},
      {"NaN dip being learnt", [](GaussNewtonState& st) {
         st.dip_sum_rad = std::nan("");
         st.dip_n = 10;  // still learning: the next sample averages the NaN in
       }},
  };
  for (const Case& c : cases) {
    sim::SimConfig cfg = sim::make_scenario("static_magnet", 100.0, 5);
    cfg.magnets.clear();
    cfg.duration_s = 5.0;
    sim::SensorSimulator sim(cfg);
    GaussNewton hit;
    GaussNewton clean;
    for (int k = 0; !sim.done(); ++k) {
      const ImuSample s = sim.next().imu;
      if (k == 200) {
        GaussNewtonState st = hit.state();
        c.spoil(st);
        hit.set_state(st);
        EXPECT_FALSE(hit.update(s)) << c.name;  // the resetting update
        EXPECT_FALSE(hit.initialized()) << c.name;
        EXPECT_STREQ(hit.sources()[0].reason, kStateResetReason) << c.name;
      } else {
        hit.update(s);
      }
      clean.update(s);
      ASSERT_TRUE(hit.result().q_world_body.coeffs().allFinite() || !hit.initialized()) << c.name << " at " << k;
    }
    EXPECT_EQ(hit.state_resets(), 1u) << c.name;
    EXPECT_EQ(hit.rejections().total(), 0u) << c.name;
    EXPECT_LT(quat_angle_between(hit.result().q_world_body, clean.result().q_world_body) * kDegPerRad,
              kSameAsCleanDeg)
        << c.name;
  }
}

}  // namespace
}  // namespace poise

namespace poise {
namespace {

// The published covariance (issue 31) against the simulated truth: the least-squares covariance
// with the residual's variance. Band: the for correlated samples (median NEES 1-5, at
// least 85 % inside the 95 % ellipsoid); chi-square with 3 degrees of freedom: median 2.366.
constexpr double kMinMedianNees = 1.0;
constexpr double kMaxMedianNees = 5.0;
constexpr double kMinInside95 = 0.85;

TEST(GaussNewtonConsistency, GivenASensorWithWhiteNoiseAndAccelerationsThenTheNeesLiesInTheBandAndNeverAllZero) {
  // GIVEN the simulator's noisy sensor (accelerometer 0.04 m/s^2, magnetometer 0.2 uT per sample)
  // at rest and in random motion with external accelerations; no magnet
  for (const char* scenario : {"static_magnet", "random_motion"}) {
    sim::SimConfig cfg = sim::make_scenario(scenario, 200.0, 7);
    cfg.magnets.clear();
    sim::SensorSimulator simu(cfg);
    GaussNewton gn;
    NeesSummary nees;
    // WHEN it solves every sample
    while (!simu.done()) {
      const sim::SimSample s = simu.next();
      if (!gn.update(s.imu) || s.truth.t_s < 1.0) {
        continue;
      }
      const Eigen::Matrix3d p = gn.attitude_covariance();
      ASSERT_GT(p.diagonal().minCoeff(), 0.0) << "never an all-zero covariance";
      nees.add(attitude_nees(world_attitude_error(gn.result().q_world_body, s.truth.q_world_body), p));
    }
    std::printf("%s: median NEES %.2f, %.1f %% inside the 95 %% ellipsoid, %zu samples\n", scenario, nees.median(),
                100.0 * nees.fraction_inside(), nees.samples());
    // THEN it lies in the band
    EXPECT_EQ(nees.without_covariance(), 0u);
    EXPECT_GE(nees.median(), kMinMedianNees) << scenario;
    EXPECT_LE(nees.median(), kMaxMedianNees) << scenario;
    EXPECT_GE(nees.fraction_inside(), kMinInside95) << scenario;
  }
}

}  // namespace
}  // namespace poise
