// Paper 003 Table 3 claims reproduced on the seeded simulator (with margins), plus simulator
// sanity checks.
#include "poise/eval/altitude_eval.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace poise {
namespace {

constexpr uint64_t kSeeds[] = {1, 2, 3};
/// Paper: 0.115 m/s for method 3 on test 1; the issue asks for <= 0.12 m/s.
constexpr double kTest1VelocityRmseMaxMps = 0.12;
/// Method 3 must beat method 2 by at least this factor (mean RMSE over the seeds).
constexpr double kBeatFactor = 0.95;

double mean_velocity_rmse(const std::string& profile, AltitudeMethod method, CfGains gains) {
  double sum = 0.0;
  for (uint64_t seed : kSeeds) {
    AltitudeSimConfig sim;
    sim.profile = profile;
    sim.seed = seed;
    AltitudeParams p;
    p.method = method;
    p.gains = gains;
    const AltitudeScore s = score_altitude(sim, p);
    EXPECT_GT(s.samples, 1000U) << profile << " seed " << seed;
    EXPECT_EQ(s.rejects.total(), 0U);
    sum += s.velocity_rmse_mps;
  }
  return sum / static_cast<double>(std::size(kSeeds));
}

TEST(AltitudeSim, GivenTest1WhenMethod3ThenVelocityRmseAtMost012) {
  for (uint64_t seed : kSeeds) {
    AltitudeSimConfig sim;
    sim.profile = "random";
    sim.seed = seed;
    const AltitudeScore s = score_altitude(sim, AltitudeParams{});
    EXPECT_LE(s.velocity_rmse_mps, kTest1VelocityRmseMaxMps) << "seed " << seed;
    EXPECT_LT(s.height_rmse_m, s.baro_height_rmse_m) << "the filter must beat the raw baro height";
  }
}

/// Paper 003: method 3 (PI CF + ZUPT) beats method 2 (CF + ZUPT) on tests 1, 2 and 5.
class AltitudeMethod3Beats2 : public ::testing::TestWithParam<const char*> {};

TEST_P(AltitudeMethod3Beats2, WithDefaultHigginsGains) {
  const double m2 = mean_velocity_rmse(GetParam(), AltitudeMethod::kCfZupt, CfGains::kHiggins);
  const double m3 = mean_velocity_rmse(GetParam(), AltitudeMethod::kPiCfZupt, CfGains::kHiggins);
  EXPECT_LT(m3, kBeatFactor * m2) << GetParam() << ": method 3 " << m3 << " m/s, method 2 " << m2;
}

INSTANTIATE_TEST_SUITE_P(Tests1_2_5, AltitudeMethod3Beats2,
                         ::testing::Values("random", "random_fast", "climb_descend_3m"));

TEST(AltitudeSim, GivenTest1ThenTwoStepKfAndConventionalCfAreAlike) {
  // Paper 003 Table 3: methods 1 and 2 perform alike (0.2046 vs 0.2033 m/s on test 1); with the
  // Higgins gains the CF is the KF's steady state.
  constexpr double kAlikeFactor = 1.1;
  const double m1 = mean_velocity_rmse("random", AltitudeMethod::kTwoStepKf, CfGains::kHiggins);
  const double m2 = mean_velocity_rmse("random", AltitudeMethod::kCfZupt, CfGains::kHiggins);
  EXPECT_LT(m1, kAlikeFactor * m2);
  EXPECT_LT(m2, kAlikeFactor * m1);
}

TEST(AltitudeSim, GivenStairsWhenZuptThenMethods2And3AreClose) {
  // Paper: on tests 3 and 4 the integral term adds little because ZUPT already removes the drift.
  constexpr double kCloseFactor = 1.25;
  for (const char* profile : {"stairs_1_5m", "stairs_3m"}) {
    const double m2 = mean_velocity_rmse(profile, AltitudeMethod::kCfZupt, CfGains::kHiggins);
    const double m3 = mean_velocity_rmse(profile, AltitudeMethod::kPiCfZupt, CfGains::kHiggins);
    EXPECT_LT(m3, kCloseFactor * m2) << profile;
    EXPECT_LT(m2, kCloseFactor * m3) << profile;
    // Without ZUPT the stops are not exploited: clearly worse (Fig. 8).
    const double m3_no_zupt = mean_velocity_rmse(profile, AltitudeMethod::kPiCf, CfGains::kHiggins);
    EXPECT_GT(m3_no_zupt, 1.5 * m3) << profile;
  }
}

TEST(AltitudeSim, GivenStairsThenDetectorFlagsTheStops) {
  // GIVEN stops of 2.5 s WHEN the ZUPT detector runs THEN it flags most of the truly still time
  // and (almost) nothing else.
  AltitudeSimConfig sim;
  sim.profile = "stairs_3m";
  sim.seed = 7;
  const auto samples = simulate_altitude(sim);
  AltitudeFilter f;
  std::size_t true_still = 0;
  std::size_t hit = 0;
  std::size_t false_alarm = 0;
  for (const auto& s : samples) {
    f.update(s.imu);
    true_still += s.true_stationary ? 1U : 0U;
    if (f.estimate().stationary) {
      (s.true_stationary ? hit : false_alarm) += 1U;
    }
  }
  ASSERT_GT(true_still, 0U);
  EXPECT_GT(static_cast<double>(hit) / static_cast<double>(true_still), 0.8);
  EXPECT_LT(static_cast<double>(false_alarm) / static_cast<double>(samples.size()), 0.02);
}

TEST(AltitudeSim, SameSeedSameRunOtherSeedOtherRun) {
  AltitudeSimConfig a;
  a.seed = 11;
  AltitudeSimConfig b = a;
  AltitudeSimConfig c = a;
  c.seed = 12;
  const auto ra = simulate_altitude(a);
  const auto rb = simulate_altitude(b);
  const auto rc = simulate_altitude(c);
  ASSERT_EQ(ra.size(), rb.size());
  bool differs = false;
  for (std::size_t k = 0; k < ra.size(); ++k) {
    ASSERT_EQ(ra[k].imu.accel_mps2, rb[k].imu.accel_mps2);
    ASSERT_EQ(ra[k].imu.pressure_pa, rb[k].imu.pressure_pa);
    differs = differs || ra[k].imu.accel_mps2 != rc[k].imu.accel_mps2;
  }
  EXPECT_TRUE(differs);
}

TEST(AltitudeSim, NoiselessSimulatorIsConsistent) {
  // GIVEN every noise, bias and drift off WHEN a profile is simulated THEN the barometer gives
  // the true height and, at rest, the accelerometer reads +g along up.
  AltitudeSimConfig sim;
  sim.profile = "climb_descend_3m";
  sim.accel_noise_mps2 = 0.0;
  sim.accel_bias_max_mps2 = 0.0;
  sim.gyro_noise_rps = 0.0;
  sim.gyro_bias_max_rps = 0.0;
  sim.baro_noise_pa = 0.0;
  sim.baro_drift_pa_per_sqrt_s = 0.0;
  sim.baro_resolution_pa = 0.0;
  const auto samples = simulate_altitude(sim);
  double max_top = 0.0;
  for (const auto& s : samples) {
    EXPECT_NEAR(baro_height_m(s.imu.pressure_pa, sim.reference_pressure_pa), s.true_height_m, 1e-6);
    if (s.true_stationary) {
      EXPECT_NEAR(s.imu.accel_mps2.norm(), IsaConstants::kG, 1e-9);
      EXPECT_NEAR(s.imu.gyro_rps.norm(), 0.0, 1e-12);
    }
    max_top = std::max(max_top, s.true_height_m - sim.ground_height_m);
  }
  EXPECT_NEAR(max_top, 3.0, 1e-9);
  EXPECT_THROW(simulate_altitude(AltitudeSimConfig{"nowhere"}), std::invalid_argument);
}

TEST(AltitudeSim, NoiselessRunIsNearlyExact) {
  // GIVEN a noiseless random test WHEN method 3 runs THEN what remains is the tilt KF's lag under
  // up to 4 m/s^2 of external acceleration and the model's discretisation (measured 0.017 m/s),
  // well below the noisy figure (~0.05 m/s): a sign or frame error would give metres per second.
  constexpr double kExactVelTolMps = 0.025;
  AltitudeSimConfig sim;
  sim.profile = "random";
  sim.accel_noise_mps2 = 0.0;
  sim.accel_bias_max_mps2 = 0.0;
  sim.gyro_noise_rps = 0.0;
  sim.gyro_bias_max_rps = 0.0;
  sim.baro_noise_pa = 0.0;
  sim.baro_drift_pa_per_sqrt_s = 0.0;
  sim.baro_resolution_pa = 0.0;
  const AltitudeScore s = score_altitude(sim, AltitudeParams{});
  EXPECT_LT(s.velocity_rmse_mps, kExactVelTolMps);
}

}  // namespace
}  // namespace poise
