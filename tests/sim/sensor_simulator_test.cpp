// The simulator's signals are consistent with its truth (closed-form checks in simulated time).
#include "poise/sim/sensor_simulator.h"

#include "poise/core/attitude.h"

#include <gtest/gtest.h>

namespace poise::sim {
namespace {

constexpr double kGyroIntegrationTolDeg = 0.05;  // deg over the whole run, noise-free
constexpr double kSpecificForceTol = 1e-6;       // m/s^2, noise-free
constexpr double kMagTolUt = 1e-9;               // uT, noise-free

SimConfig noise_free(SimConfig c) {
  c.noise.sigma_gyro_rps = 0.0;
  c.noise.sigma_accel_mps2 = 0.0;
  c.noise.sigma_mag_ut = 0.0;
  c.noise.sigma_pressure_pa = 0.0;
  return c;
}

TEST(SensorSimulator, GivenFastMotionWhenGyroIsIntegratedThenItReproducesTheTrueAttitude) {
  SensorSimulator sim(noise_free(make_scenario("fast_motion", 200.0, 7)));
  SimSample s = sim.next();
  Eigen::Quaterniond q = s.truth.q_world_body;
  Eigen::Vector3d prev_gyro = s.imu.gyro_rps - s.truth.gyro_bias_rps;
  double max_err_deg = 0.0;
  double max_rate = 0.0;
  while (!sim.done()) {
    s = sim.next();
    const Eigen::Vector3d gyro = s.imu.gyro_rps - s.truth.gyro_bias_rps;
    q = quat_integrate_body_rate(q, 0.5 * (prev_gyro + gyro), 1.0 / 200.0);  // trapezoid
    prev_gyro = gyro;
    max_rate = std::max(max_rate, gyro.norm());
    max_err_deg = std::max(max_err_deg, quat_angle_between(q, s.truth.q_world_body) * kDegPerRad);
    // specific force = R^T (a + g up), exactly
    const Eigen::Vector3d f = s.truth.q_world_body.conjugate() *
                              (s.truth.a_world_mps2 + 9.80665 * Eigen::Vector3d::UnitZ());
    ASSERT_LT((s.imu.accel_mps2 - f).norm(), kSpecificForceTol);
  }
  EXPECT_GT(max_rate, 2.0);  // rad/s: it is indeed fast
  EXPECT_LT(max_err_deg, kGyroIntegrationTolDeg);
}

TEST(SensorSimulator, GivenStaticMagnetScenarioThenDisturbanceFollowsTheEpisodes) {
  SensorSimulator sim(noise_free(make_scenario("static_magnet", 100.0, 3)));
  const auto samples = sim.run();
  ASSERT_EQ(samples.size(), 8000u);
  const MagneticEnvironment env;
  for (const auto& s : samples) {
    const Eigen::Vector3d expected =
        s.truth.q_world_body.conjugate() * (env.field_world_ut() + s.truth.mag_disturbance_world_ut);
    ASSERT_LT((s.imu.mag_ut - expected).norm(), kMagTolUt);
    ASSERT_FALSE(s.truth.moving);
  }
  EXPECT_LT(samples[1000].truth.mag_disturbance_world_ut.norm(), 1e-12);             // t = 10 s
  EXPECT_NEAR(samples[2500].truth.mag_disturbance_world_ut.norm(), std::sqrt(1250.0), 1e-9);  // t = 25 s, |(25,-15,20)|
  EXPECT_LT(samples[4000].truth.mag_disturbance_world_ut.norm(), 1e-12);             // t = 40 s
  // Static: the accelerometer reads g along the (fixed) world up.
  EXPECT_NEAR(samples[10].imu.accel_mps2.norm(), 9.80665, kSpecificForceTol);
  // Stamps advance by exactly 1/rate.
  EXPECT_EQ(samples[1].imu.stamp_ns - samples[0].imu.stamp_ns, 10'000'000);
}

TEST(SensorSimulator, SameSeedSameStreamDifferentSeedDifferentStream) {
  SensorSimulator a(make_scenario("random_motion", 100.0, 11));
  SensorSimulator b(make_scenario("random_motion", 100.0, 11));
  SensorSimulator c(make_scenario("random_motion", 100.0, 12));
  bool differs = false;
  for (int i = 0; i < 1500; ++i) {
    const SimSample sa = a.next();
    const SimSample sb = b.next();
    const SimSample sc = c.next();
    ASSERT_EQ(sa.imu.gyro_rps, sb.imu.gyro_rps);
    ASSERT_EQ(sa.imu.mag_ut, sb.imu.mag_ut);
    differs = differs || (sa.imu.gyro_rps - sc.imu.gyro_rps).norm() > 1e-6;
  }
  EXPECT_TRUE(differs);
}

TEST(SensorSimulator, DemoIsEndlessAndClimbsStairs) {
  SensorSimulator sim(make_scenario("demo", 50.0, 5));
  double max_alt = -1e9;
  double min_pressure = 1e9;
  double max_pressure = 0.0;
  bool saw_disturbance = false;
  for (int i = 0; i < 50 * 200; ++i) {  // 200 s
    ASSERT_FALSE(sim.done());
    const SimSample s = sim.next();
    max_alt = std::max(max_alt, s.truth.p_world_m.z());
    min_pressure = std::min(min_pressure, s.imu.pressure_pa);
    max_pressure = std::max(max_pressure, s.imu.pressure_pa);
    saw_disturbance = saw_disturbance || s.truth.mag_disturbance_world_ut.norm() > 10.0;
    ASSERT_TRUE(s.imu.accel_mps2.allFinite());
  }
  EXPECT_NEAR(max_alt, 3.0, 0.3);                  // m: one flight of stairs
  EXPECT_GT(max_pressure - min_pressure, 25.0);    // Pa: ~12 Pa/m over 3 m
  EXPECT_TRUE(saw_disturbance);
}

TEST(SensorSimulator, RejectsUnknownScenarioAndBadConfig) {
  EXPECT_THROW(make_scenario("nope"), std::invalid_argument);
  SimConfig c = make_scenario("static_magnet");
  c.rate_hz = 0.0;
  EXPECT_THROW(SensorSimulator{c}, std::invalid_argument);
}

}  // namespace
}  // namespace poise::sim
