// Calibration: YAML config, applying calibration, ellipsoid fit and the guided session.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <yaml-cpp/yaml.h>

#include "poise/imu/calibration.h"
#include "poise/imu/config.h"
#include "poise/imu/mag_calibration.h"
#include "poise/testing/testing.h"

namespace poise::imu {
namespace {

constexpr double kTightTol = 1e-12;

// Defaults in one place (issue 30): the shipped file holds no value (only the keys, as comments),
// so loading it gives exactly DriverConfig{}, every field compared; and the complete file that
// to_yaml() writes (`poise calibrate imu --output`) reads back to the same configuration.
TEST(ImuConfig, GivenTheShippedFileWhenLoadedThenItHoldsNoValueAndGivesExactlyTheStructDefaults) {
  const std::string path = poise::testing::source_path("config/drivers/imu.yaml");
  EXPECT_TRUE(YAML::LoadFile(path).IsNull()) << path << " restates values: the defaults live in the C++ structs";
  const DriverConfig c = load_driver_config(path);
  const DriverConfig d;
  EXPECT_EQ(c.serial.baud, d.serial.baud);
  EXPECT_EQ(c.serial.reconnect_initial_s, d.serial.reconnect_initial_s);
  EXPECT_EQ(c.serial.reconnect_max_s, d.serial.reconnect_max_s);
  EXPECT_EQ(c.serial.tx_correction, d.serial.tx_correction);
  EXPECT_EQ(c.params.sequence.reorder_window, d.params.sequence.reorder_window);
  EXPECT_EQ(c.params.sequence.max_forward_gap, d.params.sequence.max_forward_gap);
  EXPECT_EQ(c.params.sensor_latency_s, d.params.sensor_latency_s);
  EXPECT_EQ(c.params.link_bytes_per_s, d.params.link_bytes_per_s);
  EXPECT_EQ(c.params.limits.accel_max_mps2, d.params.limits.accel_max_mps2);
  EXPECT_EQ(c.params.limits.gyro_max_rps, d.params.limits.gyro_max_rps);
  EXPECT_EQ(c.params.limits.mag_max_ut, d.params.limits.mag_max_ut);
  EXPECT_EQ(c.params.limits.pressure_min_pa, d.params.limits.pressure_min_pa);
  EXPECT_EQ(c.params.limits.pressure_max_pa, d.params.limits.pressure_max_pa);
  EXPECT_EQ(c.params.limits.temperature_min_c, d.params.limits.temperature_min_c);
  EXPECT_EQ(c.params.limits.temperature_max_c, d.params.limits.temperature_max_c);
  EXPECT_EQ(c.params.raw.accel_lsb_per_g, d.params.raw.accel_lsb_per_g);
  EXPECT_EQ(c.params.raw.gyro_lsb_per_dps, d.params.raw.gyro_lsb_per_dps);
  EXPECT_EQ(c.params.raw.mag_lsb_per_gauss, d.params.raw.mag_lsb_per_gauss);
  EXPECT_EQ(c.params.raw.temp_lsb_per_c, d.params.raw.temp_lsb_per_c);
  EXPECT_EQ(c.params.raw.temp_offset_c, d.params.raw.temp_offset_c);
  EXPECT_EQ(c.params.raw.g_mps2, d.params.raw.g_mps2);
  EXPECT_EQ(c.params.clock.block_s, d.params.clock.block_s);
  EXPECT_EQ(c.params.clock.window_blocks, d.params.clock.window_blocks);
  EXPECT_EQ(c.params.clock.max_drift_ppm, d.params.clock.max_drift_ppm);
  EXPECT_EQ(c.params.clock.reset_threshold_s, d.params.clock.reset_threshold_s);
  EXPECT_EQ(c.params.clock.reanchor_samples, d.params.clock.reanchor_samples);
  EXPECT_EQ(c.calibration.imu_axes.to_string(), d.calibration.imu_axes.to_string());
  EXPECT_EQ(c.calibration.mag_axes.to_string(), d.calibration.mag_axes.to_string());
  EXPECT_EQ(c.calibration.gyro_bias_rps, d.calibration.gyro_bias_rps);
  EXPECT_EQ(c.calibration.gyro_scale, d.calibration.gyro_scale);
  EXPECT_EQ(c.calibration.accel_bias_mps2, d.calibration.accel_bias_mps2);
  EXPECT_EQ(c.calibration.accel_scale, d.calibration.accel_scale);
  EXPECT_EQ(c.calibration.mag_hard_iron_ut, d.calibration.mag_hard_iron_ut);
  EXPECT_EQ(c.calibration.mag_soft_iron, d.calibration.mag_soft_iron);
  const DriverConfig again = parse_driver_config(to_yaml(c), "roundtrip");
  EXPECT_EQ(to_yaml(again), to_yaml(c));
}

TEST(ImuConfig, MissingFileIsAClearError) {
  try {
    load_driver_config("/nonexistent/imu.yaml");
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/imu.yaml"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("calibrate"), std::string::npos) << e.what();
  }
}

void expect_error(const std::string& yaml, const std::string& fragment) {
  try {
    parse_driver_config(yaml, "test.yaml");
    FAIL() << "accepted: " << yaml;
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(ImuConfig, InvalidValuesNameTheKey) {
  expect_error("serial: {baud: 12345}", "serial.baud");
  expect_error("serial: {baud: fast}", "must be an integer");
  expect_error("seriall: {}", "unknown key");
  expect_error("calibration: {gyro_scale: [1, 1]}", "calibration.gyro_scale");
  expect_error("calibration: {gyro_scale: [1, 1, 5]}", "[0.5, 2]");
  expect_error("calibration: {imu_axes: \"x,x,z\"}", "twice");
  expect_error("calibration: {mag_axes: \"-x,y,z\"}", "left-handed");
  expect_error("calibration: {mag_soft_iron: [[1,0,0],[0,1,0],[0,0,0]]}", "mag_soft_iron");
  expect_error("calibration: {gyro_bias_rps: [0, .nan, 0]}", "gyro_bias_rps");
  expect_error("limits: {pressure_min_pa: 200000}", "pressure");
  expect_error("clock: {block_s: -1}", "clock.block_s");
  expect_error("[1, 2", "not valid YAML");
}

TEST(ImuCalibration, AppliesBiasScaleIronAndAxisRemap) {
  Calibration cal;
  std::string err;
  ASSERT_TRUE(AxisMap::parse("y,-x,z", &cal.imu_axes, &err)) << err;  // body x = sensor y ...
  ASSERT_TRUE(AxisMap::parse("-x,-y,z", &cal.mag_axes, &err)) << err;
  cal.gyro_bias_rps = {0.1, 0.2, 0.3};
  cal.gyro_scale = {2.0, 1.0, 1.0};
  cal.accel_bias_mps2 = {0.5, 0, 0};
  cal.mag_hard_iron_ut = {10, 20, 30};
  cal.mag_soft_iron = Eigen::Vector3d(2, 1, 1).asDiagonal();
  ASSERT_EQ(cal.validate(), "");
  RawSample raw;
  raw.gyro_rps = {1.1, 0.2, 0.3};
  raw.accel_mps2 = {0.5, 3, 9.8};
  raw.mag_ut = {11, 25, 30};
  ImuSample out;
  cal.apply(raw, &out);
  // gyro_s = [2*(1.0), 0, 0] -> body = [s.y, -s.x, s.z] = [0, -2, 0]
  EXPECT_NEAR(out.gyro_rps.x(), 0.0, kTightTol);
  EXPECT_NEAR(out.gyro_rps.y(), -2.0, kTightTol);
  EXPECT_NEAR(out.accel_mps2.x(), 3.0, kTightTol);
  EXPECT_NEAR(out.accel_mps2.y(), 0.0, kTightTol);
  EXPECT_NEAR(out.accel_mps2.z(), 9.8, kTightTol);
  // mag_s = diag(2,1,1) [1, 5, 0] = [2, 5, 0] -> body [-2, -5, 0]
  EXPECT_NEAR(out.mag_ut.x(), -2.0, kTightTol);
  EXPECT_NEAR(out.mag_ut.y(), -5.0, kTightTol);
  EXPECT_EQ(cal.imu_axes.to_string(), "+y,-x,+z");
}

TEST(ImuCalibration, InvertUndoesApply) {
  Calibration cal;
  std::string err;
  ASSERT_TRUE(AxisMap::parse("-y,x,z", &cal.imu_axes, &err)) << err;
  ASSERT_TRUE(AxisMap::parse("z,-y,x", &cal.mag_axes, &err)) << err;
  cal.gyro_bias_rps = {0.01, -0.02, 0.03};
  cal.gyro_scale = {1.1, 0.9, 1.0};
  cal.accel_bias_mps2 = {0.1, 0.2, -0.3};
  cal.accel_scale = {0.98, 1.02, 1.0};
  cal.mag_hard_iron_ut = {5, -6, 7};
  cal.mag_soft_iron << 1.1, 0.05, 0.0, 0.05, 0.95, 0.02, 0.0, 0.02, 1.0;
  ASSERT_EQ(cal.validate(), "");
  RawSample raw;
  raw.gyro_rps = {0.3, -0.2, 0.1};
  raw.accel_mps2 = {1.0, -2.0, 9.0};
  raw.mag_ut = {20, -30, 40};
  ImuSample body;
  cal.apply(raw, &body);
  const RawSample back = cal.invert(body);
  constexpr double kRoundTripTol = 1e-12;
  EXPECT_LT((back.gyro_rps - raw.gyro_rps).norm(), kRoundTripTol);
  EXPECT_LT((back.accel_mps2 - raw.accel_mps2).norm(), kRoundTripTol);
  EXPECT_LT((back.mag_ut - raw.mag_ut).norm(), kRoundTripTol);
}

// Directions spread over the sphere (seeded), true field magnitude 48 uT.
std::vector<Eigen::Vector3d> true_field(std::mt19937& rng, int n, bool half = false) {
  std::normal_distribution<double> g(0, 1);
  std::vector<Eigen::Vector3d> out;
  while (static_cast<int>(out.size()) < n) {
    Eigen::Vector3d d(g(rng), g(rng), g(rng));
    if (half && d.z() < 0) d.z() = -d.z();
    out.push_back(48.0 * d.normalized());
  }
  return out;
}

const Eigen::Matrix3d kSoftIronDistortion = (Eigen::Matrix3d() << 1.15, 0.06, -0.03,  //
                                             0.06, 0.88, 0.04,                        //
                                             -0.03, 0.04, 1.02).finished();
const Eigen::Vector3d kHardIron(14.0, -31.0, 47.0);

TEST(ImuMagFit, RecoversAKnownHardAndSoftIronDistortion) {
  // GIVEN samples of a 48 uT field seen through A (symmetric) plus offset b and 0.3 uT noise
  const unsigned seed = 42;
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, 0.3);
  std::vector<Eigen::Vector3d> raw;
  for (const auto& h : true_field(rng, 600)) {
    raw.push_back(kSoftIronDistortion * h + kHardIron + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
  }
  // WHEN fitted with the known field magnitude
  const EllipsoidFit fit = fit_ellipsoid(raw, 48.0);
  ASSERT_TRUE(fit.ok) << fit.error;
  // THEN b and A^-1 are recovered, and the corrected field has a constant magnitude
  constexpr double kHardIronTolUt = 0.2;
  constexpr double kSoftIronTol = 0.01;  // per matrix entry, dimensionless
  constexpr double kResidualTolUt = 0.5;
  EXPECT_LT((fit.hard_iron_ut - kHardIron).cwiseAbs().maxCoeff(), kHardIronTolUt)
      << fit.hard_iron_ut.transpose();
  const Eigen::Matrix3d expected = kSoftIronDistortion.inverse();
  EXPECT_LT((fit.soft_iron - expected).cwiseAbs().maxCoeff(), kSoftIronTol) << fit.soft_iron;
  EXPECT_LT(fit.residual_rms_ut, kResidualTolUt);
  EXPECT_GT(fit.spread_before_ut, 2.0);  // the distortion was visible before the fit
}

TEST(ImuMagFit, RejectsDegenerateInput) {
  EXPECT_FALSE(fit_ellipsoid({}).ok);
  std::vector<Eigen::Vector3d> flat;
  for (int i = 0; i < 100; ++i) {
    flat.emplace_back(std::cos(i * 0.1) * 40, std::sin(i * 0.1) * 40, 5.0);  // one plane only
  }
  const EllipsoidFit f = fit_ellipsoid(flat);
  EXPECT_FALSE(f.ok);
  EXPECT_FALSE(f.error.empty());
}

TEST(ImuMagFit, CoverageReflectsTheOrientationsSeen) {
  std::mt19937 rng(3);
  SphereCoverage full;
  SphereCoverage half;
  for (const auto& h : true_field(rng, 3000)) full.add(h);
  for (const auto& h : true_field(rng, 3000, true)) half.add(h);
  EXPECT_GT(full.fraction(), 0.99);
  // Bins straddling the equator are hit from the upper side too.
  EXPECT_GT(half.fraction(), 0.45);
  EXPECT_LT(half.fraction(), 0.7);
}

TEST(ImuCalibrationSession, StillThenRotateRecoversGyroBiasAndIron) {
  // GIVEN 2 s of motion, 6 s still (gyro bias b_g), then a tumbling rotation (seeded)
  const unsigned seed = 9;
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, 1);
  const Eigen::Vector3d gyro_bias(0.012, -0.021, 0.004);
  constexpr double kGyroNoiseRps = 0.002;
  CalibrationParams p;
  p.still_s = 4.0;
  CalibrationSession session(p);
  int64_t t = 0;
  constexpr int64_t kDtNs = 10'000'000;  // 100 Hz
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  const Eigen::Vector3d h_world(0, 20.0, -43.0);
  for (int k = 0; k < 100 * 120 && !session.done(); ++k, t += kDtNs) {
    const double ts = static_cast<double>(t) * 1e-9;
    Eigen::Vector3d w = Eigen::Vector3d::Zero();
    if (ts < 2.0) {
      w = Eigen::Vector3d(1.0, 0.5, -0.3);
    } else if (ts >= 8.0) {
      w = Eigen::Vector3d(1.3 * std::sin(0.31 * ts), 0.9 * std::cos(0.17 * ts), 1.1 * std::sin(0.07 * ts + 1.0));
    }
    q = (q * Eigen::Quaterniond(Eigen::AngleAxisd(w.norm() * 0.01, w.norm() > 0 ? w.normalized()
                                                                                  : Eigen::Vector3d::UnitX())))
            .normalized();
    RawSample s;
    s.gyro_rps = w + gyro_bias + kGyroNoiseRps * Eigen::Vector3d(n(rng), n(rng), n(rng));
    s.accel_mps2 = q.conjugate() * Eigen::Vector3d(0, 0, 9.81) + 0.01 * Eigen::Vector3d(n(rng), n(rng), n(rng));
    s.mag_ut = kSoftIronDistortion * (q.conjugate() * h_world) + kHardIron +
               0.2 * Eigen::Vector3d(n(rng), n(rng), n(rng));
    session.add(s, t);
  }
  // THEN the session finished on its own with the bias and the iron recovered
  ASSERT_TRUE(session.done()) << "coverage " << session.progress().coverage;
  ASSERT_TRUE(session.has_gyro_bias());
  constexpr double kGyroBiasTolRps = 5e-4;
  EXPECT_LT((session.gyro_bias_rps() - gyro_bias).cwiseAbs().maxCoeff(), kGyroBiasTolRps);
  const EllipsoidFit& fit = session.mag_fit();
  ASSERT_TRUE(fit.ok) << fit.error;
  constexpr double kHardIronTolUt = 0.5;
  constexpr double kShapeTol = 0.02;  // soft iron up to the unknown field magnitude
  EXPECT_LT((fit.hard_iron_ut - kHardIron).cwiseAbs().maxCoeff(), kHardIronTolUt);
  const Eigen::Matrix3d expected = kSoftIronDistortion.inverse() * (fit.field_ut / h_world.norm());
  EXPECT_LT((fit.soft_iron - expected).cwiseAbs().maxCoeff(), kShapeTol) << fit.soft_iron;
  EXPECT_NEAR(fit.field_ut, h_world.norm(), 2.0);
}

}  // namespace
}  // namespace poise::imu
