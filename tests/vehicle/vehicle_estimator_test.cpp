// Vehicle attitude (paper 001): TRIAD closed forms, EKF convergence, switching, bad input, config.
#include "poise/vehicle/vehicle_estimator.h"

#include "poise/core/attitude.h"
#include "poise/testing/one_hostile_sample.h"
#include "poise/testing/param_errors.h"
#include "poise/testing/state_round_trip.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <vector>
#include <stdexcept>

namespace poise {
namespace {

constexpr double kG = 9.80665;
constexpr double kExactTolRad = 1e-9;
constexpr int64_t kStepNs = 10'000'000;  // 100 Hz

/// Noiseless static sample of a vehicle at (roll, 0, yaw) on the default field.
VehicleSample static_sample(int64_t stamp_ns, double roll, double pitch, double yaw,
                            const Eigen::Vector3d& h = VehicleParams{}.mag_world_ut) {
  const Eigen::Matrix3d r = body_world_from_euler(roll, pitch, yaw);
  const Eigen::Vector3d f = r * Eigen::Vector3d(0.0, 0.0, kG);
  VehicleSample s;
  s.stamp_ns = stamp_ns;
  s.accel_lon_mps2 = f.x();
  s.accel_lat_mps2 = f.y();
  s.yaw_rate_rps = 0.0;
  s.mag_ut = r * h;
  s.has_mag = true;
  s.speed_mps = 0.0;
  return s;
}

TEST(VehicleMath, MatrixOneMatchesThePrintedEntries) {
  // (1) with C/S of roll f, pitch t, yaw p, (1,2) = C(t)S(p) (the print of (12) has C(t)C(p)).
  const double f = 0.3;
  const double t = -0.2;
  const double p = 1.1;
  const Eigen::Matrix3d r = body_world_from_euler(f, t, p);
  using std::cos;
  using std::sin;
  Eigen::Matrix3d printed;
  printed << cos(t) * cos(p), cos(t) * sin(p), -sin(t),
      -cos(f) * sin(p) + sin(f) * sin(t) * cos(p), cos(f) * cos(p) + sin(f) * sin(t) * sin(p), sin(f) * cos(t),
      sin(f) * sin(p) + cos(f) * sin(t) * cos(p), -sin(f) * cos(p) + cos(f) * sin(t) * sin(p), cos(f) * cos(t);
  EXPECT_TRUE(r.isApprox(printed, 1e-12));
  const Eigen::Vector3d e = euler_from_body_world(r);  // (10)
  EXPECT_NEAR(e(0), f, kExactTolRad);
  EXPECT_NEAR(e(1), t, kExactTolRad);
  EXPECT_NEAR(e(2), p, kExactTolRad);
}

TEST(VehicleTriad, ExactOnStaticSyntheticDataWithoutGrade) {
  // GIVEN a vehicle at rest with any roll and yaw and no pitch (the virtual gravity (7) assumes
  // no longitudinal slope) WHEN TRIAD runs THEN it returns the exact angles.
  const Eigen::Vector3d h = VehicleParams{}.mag_world_ut;
  for (double roll : {-0.35, -0.1, 0.0, 0.2, 0.35}) {
    for (double yaw : {-3.0, -1.2, 0.0, 0.7, 2.9}) {
      const VehicleSample s = static_sample(0, roll, 0.0, yaw);
      Eigen::Matrix3d r;
      ASSERT_TRUE(triad_body_world(s.mag_ut, s.accel_lat_mps2 / kG, h, r));
      const Eigen::Vector3d e = euler_from_body_world(r);
      EXPECT_NEAR(e(0), roll, kExactTolRad) << roll << " " << yaw;
      EXPECT_NEAR(e(1), 0.0, kExactTolRad);
      EXPECT_NEAR(wrap_angle(e(2) - yaw), 0.0, kExactTolRad);
      // The magnetometer is reproduced exactly (TRIAD's anchor vector).
      EXPECT_TRUE((r * h).isApprox(s.mag_ut, 1e-12));
    }
  }
}

TEST(VehicleTriad, GradeIsNotObservedByTheVirtualGravity) {
  // GIVEN a 5 deg grade at rest WHEN TRIAD runs THEN the magnetometer is still matched exactly but
  // the angles are off (documented limitation of (7)).
  const VehicleSample s = static_sample(0, 0.0, -5.0 * kRadPerDeg, 0.4);
  Eigen::Matrix3d r;
  ASSERT_TRUE(triad_body_world(s.mag_ut, s.accel_lat_mps2 / kG, VehicleParams{}.mag_world_ut, r));
  const Eigen::Vector3d e = euler_from_body_world(r);
  EXPECT_GT(std::abs(e(1) + 5.0 * kRadPerDeg) + std::abs(e(2) - 0.4) + std::abs(e(0)), 1e-3);
  EXPECT_TRUE((r * VehicleParams{}.mag_world_ut).isApprox(s.mag_ut, 1e-12));
}

TEST(VehicleTriad, DegenerateInputFails) {
  Eigen::Matrix3d r;
  EXPECT_FALSE(triad_body_world(Eigen::Vector3d::Zero(), 0.0, VehicleParams{}.mag_world_ut, r));
  // Field parallel to the virtual gravity.
  EXPECT_FALSE(triad_body_world(Eigen::Vector3d(0.0, 0.0, 40.0), 0.0, VehicleParams{}.mag_world_ut, r));
  EXPECT_FALSE(triad_body_world(Eigen::Vector3d(std::nan(""), 1.0, 1.0), 0.0,
                                VehicleParams{}.mag_world_ut, r));
}

TEST(VehicleEstimator, GivenStandstillThenSwitchedUsesTriadExactly) {
  VehicleEstimator est;
  for (int k = 0; k < 50; ++k) {
    ASSERT_TRUE(est.update(static_sample(k * kStepNs, 0.1, 0.0, 1.0)));
  }
  const auto& e = est.estimate();
  EXPECT_TRUE(e.valid);
  EXPECT_TRUE(e.is_static);
  EXPECT_TRUE(e.from_triad);
  EXPECT_NEAR(e.roll_rad, 0.1, kExactTolRad);
  EXPECT_NEAR(e.pitch_rad, 0.0, kExactTolRad);
  EXPECT_NEAR(e.yaw_rad, 1.0, kExactTolRad);
  const Eigen::Vector3d rpy = euler_zyx_from_quat(e.q_world_body);
  EXPECT_NEAR(rpy(0), 0.1, 1e-9);
  EXPECT_NEAR(rpy(2), 1.0, 1e-9);
}

TEST(VehicleEstimator, GivenWrongStartWhenDrivingStraightThenEkfConverges) {
  // GIVEN an EKF-only estimator initialised 15 deg off in yaw (first sample's magnetometer rotated)
  // WHEN the vehicle drives straight and level at 20 m/s with noiseless sensors for 20 s
  // THEN roll, pitch and yaw converge to the truth.
  constexpr double kConvergedTolRad = 0.2 * kRadPerDeg;
  VehicleParams p;
  p.mode = VehicleMode::kEkf;
  VehicleEstimator est(p);
  const double yaw = 0.8;
  VehicleSample first = static_sample(0, 0.0, 0.0, yaw + 15.0 * kRadPerDeg);
  first.speed_mps = 20.0;
  ASSERT_TRUE(est.update(first));
  EXPECT_NEAR(est.estimate().yaw_rad, yaw + 15.0 * kRadPerDeg, 1e-9);
  for (int k = 1; k <= 2000; ++k) {
    VehicleSample s = static_sample(k * kStepNs, 0.0, 0.0, yaw);
    s.speed_mps = 20.0;
    ASSERT_TRUE(est.update(s));
  }
  const auto& e = est.estimate();
  EXPECT_FALSE(e.from_triad);
  EXPECT_FALSE(e.is_static);
  EXPECT_NEAR(e.roll_rad, 0.0, kConvergedTolRad);
  EXPECT_NEAR(e.pitch_rad, 0.0, kConvergedTolRad);
  EXPECT_NEAR(wrap_angle(e.yaw_rad - yaw), 0.0, kConvergedTolRad);
  // The covariance stays symmetric positive definite.
  const auto& pm = est.ekf_covariance();
  EXPECT_TRUE(pm.isApprox(pm.transpose(), 1e-12));
  EXPECT_GT(pm.llt().info() == Eigen::Success ? 1 : 0, 0);
}

TEST(VehicleEstimator, GivenSteadyTurnThenEkfMatchesTheSuspensionEquilibrium) {
  // GIVEN a steady flat turn with lateral specific force a_y (model exact, noiseless) WHEN the EKF
  // runs THEN roll settles at m_s h_s a_y / k_x (roll out of the turn), the equilibrium of (11).
  VehicleParams p;
  p.mode = VehicleMode::kEkf;
  VehicleEstimator est(p);
  const double v = 20.0;
  const double ay = 3.0;  // m/s^2, left turn
  const double r = ay / v;
  const double roll_eq = p.model.m_s_kg * p.model.h_s_m * ay / p.model.k_x_nm_per_rad;
  double yaw = 0.0;
  for (int k = 0; k < 3000; ++k) {
    // Body roll phi = roll_eq: the accelerometer sees the specific force of the turn plus gravity.
    const Eigen::Matrix3d rbw = body_world_from_euler(roll_eq, 0.0, yaw);
    const Eigen::Vector3d a_w(-ay * std::sin(yaw), ay * std::cos(yaw), 0.0);  // centripetal
    const Eigen::Vector3d f = rbw * (a_w + Eigen::Vector3d(0.0, 0.0, kG));
    VehicleSample s;
    s.stamp_ns = k * kStepNs;
    s.accel_lon_mps2 = f.x();
    s.accel_lat_mps2 = f.y();
    s.yaw_rate_rps = std::cos(roll_eq) * r;
    s.mag_ut = rbw * p.mag_world_ut;
    s.has_mag = true;
    s.speed_mps = v;
    ASSERT_TRUE(est.update(s));
    yaw = wrap_angle(yaw + r * 0.01);
  }
  EXPECT_GT(roll_eq, 0.0);
  EXPECT_NEAR(est.estimate().roll_rad, roll_eq, 0.3 * kRadPerDeg);
  EXPECT_NEAR(wrap_angle(est.estimate().yaw_rad - (yaw - r * 0.01)), 0.0, 0.5 * kRadPerDeg);
}

TEST(VehicleEstimator, BadInputIsRejectedAndCounted) {
  VehicleEstimator est;
  int64_t t = 0;
  for (int k = 0; k < 10; ++k, t += kStepNs) {
    ASSERT_TRUE(est.update(static_sample(t, 0.05, 0.0, 0.3)));
  }
  VehicleSample s = static_sample(t, 0.05, 0.0, 0.3);
  s.accel_lat_mps2 = std::nan("");
  EXPECT_FALSE(est.update(s));
  s = static_sample(t, 0.05, 0.0, 0.3);
  s.yaw_rate_rps = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(est.update(s));
  EXPECT_EQ(est.rejects().samples.count(RejectReason::kNonFiniteAccel), 1U);
  EXPECT_EQ(est.rejects().samples.count(RejectReason::kNonFiniteGyro), 1U);

  // Negative, NaN and missing speed: counted, the last valid speed is kept, the sample is used.
  for (int i = 0; i < 3; ++i) {
    s = static_sample(t, 0.05, 0.0, 0.3);
    if (i == 0) {
      s.speed_mps = -1.0;
    } else if (i == 1) {
      s.speed_mps = std::nan("");
    } else {
      s.has_speed = false;
    }
    EXPECT_TRUE(est.update(s));
    t += kStepNs;
  }
  EXPECT_EQ(est.rejects().bad_speed, 3U);

  // Missing or NaN magnetometer: counted; the output stays finite.
  s = static_sample(t, 0.05, 0.0, 0.3);
  s.has_mag = false;
  EXPECT_TRUE(est.update(s));
  t += kStepNs;
  s = static_sample(t, 0.05, 0.0, 0.3);
  s.mag_ut.x() = std::nan("");
  EXPECT_TRUE(est.update(s));
  t += kStepNs;
  EXPECT_EQ(est.rejects().missing_mag, 1U);
  EXPECT_EQ(est.rejects().samples.count(RejectReason::kNonFiniteMag), 1U);
  // A field three times too strong (magnet nearby): disturbed.
  s = static_sample(t, 0.05, 0.0, 0.3);
  s.mag_ut *= 3.0;
  EXPECT_TRUE(est.update(s));
  t += kStepNs;
  EXPECT_EQ(est.rejects().disturbed_mag, 1U);
  EXPECT_TRUE(std::isfinite(est.estimate().roll_rad));
  EXPECT_NEAR(est.estimate().roll_rad, 0.05, 1e-6);

  // Stamps that do not advance.
  EXPECT_FALSE(est.update(static_sample(t - kStepNs, 0.05, 0.0, 0.3)));
  EXPECT_EQ(est.rejects().samples.count(RejectReason::kNonMonotonicStamp), 1U);
  t += 100 * kStepNs;  // a gap: refused, counted
  EXPECT_FALSE(est.update(static_sample(t, 0.05, 0.0, 0.3)));
  EXPECT_EQ(est.rejects().samples.count(RejectReason::kTimeGap), 1U);
  EXPECT_EQ(est.rejects().total(), 10U);
}

// Issue 19: one hostile sample between valid ones while driving (EKF running) is refused by the
// shared sample check, counted exactly once under its reason, and leaves the state untouched: the
// output afterwards is that of an estimator that never saw it. An impossible magnetometer refuses
// only the magnetometer: the oracle then got the same sample without one.
TEST(VehicleEstimator, GivenOneHostileSampleThenItIsCountedOnceAndTheOutputIsThatOfAnEstimatorThatNeverSawIt) {
  constexpr double kSameAsCleanRad = 1e-12;  // rad: the state is untouched, so equal
  constexpr int kHostileAt = 300;
  constexpr int kSamples = 600;
  const double r = 0.1;  // rad/s: a turn at 15 m/s, the switched estimator runs its EKF
  const auto sample = [r](int k) {
    VehicleSample s = static_sample(k * kStepNs, 0.02, -0.01, wrap_angle(r * k * 0.01));
    s.yaw_rate_rps = r;
    s.speed_mps = 15.0;
    return s;
  };
  struct Case {
    const char* name;
    std::function<void(VehicleSample&)> spoil;
    RejectReason reason;
    bool whole_sample;  // false: only the magnetometer is refused
  };
  const std::vector<Case> cases = {
      {"accel 1e308", [](VehicleSample& s) { s.accel_lon_mps2 = 1e308; }, RejectReason::kAccelOutOfRange, true},
      {"yaw rate 1e308", [](VehicleSample& s) { s.yaw_rate_rps = 1e308; }, RejectReason::kGyroOutOfRange, true},
      {"accel NaN", [](VehicleSample& s) { s.accel_lat_mps2 = std::nan(""); }, RejectReason::kNonFiniteAccel, true},
      {"stamp INT64_MAX", [](VehicleSample& s) { s.stamp_ns = std::numeric_limits<int64_t>::max(); },
       RejectReason::kStampOutOfRange, true},
      {"stamp INT64_MIN", [](VehicleSample& s) { s.stamp_ns = std::numeric_limits<int64_t>::min(); },
       RejectReason::kStampOutOfRange, true},
      {"stamp -1 ns", [](VehicleSample& s) { s.stamp_ns = -1; }, RejectReason::kStampOutOfRange, true},
      {"stamp back 10 ms", [](VehicleSample& s) { s.stamp_ns -= kStepNs; }, RejectReason::kNonMonotonicStamp, true},
      {"stamp +1e15 ns", [](VehicleSample& s) { s.stamp_ns += 1'000'000'000'000'000; }, RejectReason::kTimeGap, true},
      {"mag 1e308", [](VehicleSample& s) { s.mag_ut.y() = 1e308; }, RejectReason::kMagOutOfRange, false},
      {"mag NaN", [](VehicleSample& s) { s.mag_ut.z() = std::nan(""); }, RejectReason::kNonFiniteMag, false},
  };
  for (const Case& c : cases) {
    VehicleEstimator e;
    VehicleEstimator clean;
    const bool used = testing::run_with_one_hostile_sample(
        e, clean, kSamples, kHostileAt, kStepNs / 2, c.whole_sample, sample, c.spoil,
        [](VehicleSample& s) { s.has_mag = false; });
    EXPECT_EQ(used, !c.whole_sample) << c.name;
    EXPECT_EQ(e.rejects().samples.count(c.reason), 1u) << c.name;
    EXPECT_EQ(e.rejects().samples.total(), 1u) << c.name;
    EXPECT_EQ(e.state_resets(), 0u) << c.name;
    ASSERT_TRUE(e.estimate().valid) << c.name;
    EXPECT_FALSE(e.estimate().from_triad) << c.name;
    EXPECT_NEAR(e.estimate().roll_rad, clean.estimate().roll_rad, kSameAsCleanRad) << c.name;
    EXPECT_NEAR(e.estimate().pitch_rad, clean.estimate().pitch_rad, kSameAsCleanRad) << c.name;
    EXPECT_NEAR(wrap_angle(e.estimate().yaw_rad - clean.estimate().yaw_rad), 0.0, kSameAsCleanRad) << c.name;
  }
}

TEST(VehicleEstimator, MissingMagnetometerWhileDrivingPredictsOnly) {
  VehicleParams p;
  p.mode = VehicleMode::kEkf;
  VehicleEstimator est(p);
  VehicleSample s = static_sample(0, 0.0, 0.0, 0.5);
  s.speed_mps = 15.0;
  ASSERT_TRUE(est.update(s));
  for (int k = 1; k < 100; ++k) {
    s = static_sample(k * kStepNs, 0.0, 0.0, 0.5);
    s.speed_mps = 15.0;
    s.has_mag = false;
    ASSERT_TRUE(est.update(s));
  }
  EXPECT_EQ(est.rejects().missing_mag, 99U);
  EXPECT_NEAR(est.estimate().yaw_rad, 0.5, 1e-9);
  // The yaw variance grew with no magnetometer to bound it.
  EXPECT_GT(est.ekf_covariance()(4, 4), p.initial_var_angle_rad2);
}

// Defaults in one place: the shipped file holds only what differs from VehicleParams{} (nothing),
// so loading it gives exactly the struct, every field compared.
TEST(VehicleConfig, ShippedYamlIsExactlyTheDefaultsFieldByField) {
  const VehicleParams p = load_vehicle_params(testing::source_path("config/filters/vehicle.yaml"));
  const VehicleParams d;
  EXPECT_EQ(p.model.i_x_kgm2, d.model.i_x_kgm2);
  EXPECT_EQ(p.model.i_y_kgm2, d.model.i_y_kgm2);
  EXPECT_EQ(p.model.k_x_nm_per_rad, d.model.k_x_nm_per_rad);
  EXPECT_EQ(p.model.k_y_nm_per_rad, d.model.k_y_nm_per_rad);
  EXPECT_EQ(p.model.b_x_nms_per_rad, d.model.b_x_nms_per_rad);
  EXPECT_EQ(p.model.b_y_nms_per_rad, d.model.b_y_nms_per_rad);
  EXPECT_EQ(p.model.m_s_kg, d.model.m_s_kg);
  EXPECT_EQ(p.model.h_s_m, d.model.h_s_m);
  EXPECT_EQ(p.mode, d.mode);
  EXPECT_EQ(p.gravity_mps2, d.gravity_mps2);
  EXPECT_EQ(p.mag_world_ut, d.mag_world_ut);
  EXPECT_EQ(p.static_yaw_rate_max_rps, d.static_yaw_rate_max_rps);
  EXPECT_EQ(p.static_speed_max_mps, d.static_speed_max_mps);
  EXPECT_EQ(p.static_average, d.static_average);
  EXPECT_EQ(p.q_roll_rad2_per_s, d.q_roll_rad2_per_s);
  EXPECT_EQ(p.q_pitch_rad2_per_s, d.q_pitch_rad2_per_s);
  EXPECT_EQ(p.q_yaw_rad2_per_s, d.q_yaw_rad2_per_s);
  EXPECT_EQ(p.r_mag_ut2, d.r_mag_ut2);
  EXPECT_EQ(p.initial_var_angle_rad2, d.initial_var_angle_rad2);
  EXPECT_EQ(p.initial_var_rate_rad2ps2, d.initial_var_rate_rad2ps2);
  EXPECT_EQ(p.max_dt_s, d.max_dt_s);
  EXPECT_EQ(p.mag_norm_tolerance, d.mag_norm_tolerance);
  EXPECT_EQ(p.max_yaw_rate_rps, d.max_yaw_rate_rps);
  EXPECT_EQ(p.max_accel_mps2, d.max_accel_mps2);
  EXPECT_EQ(p.max_mag_ut, d.max_mag_ut);
}

TEST(VehicleConfig, UnknownKeysAndBadValuesAreErrors) {
  const std::string path = ::testing::TempDir() + "/vehicle_bad.yaml";
  const auto write = [&path](const std::string& text) { std::ofstream(path) << text; };
  write("model:\n  kx: 1\n");
  EXPECT_THROW(load_vehicle_params(path), std::runtime_error);
  write("model:\n  i_x_kgm2: -3\n");
  EXPECT_THROW(load_vehicle_params(path), std::runtime_error);
  write("mag_world_ut: [0, 0, -40]\n");
  EXPECT_THROW(load_vehicle_params(path), std::runtime_error);
  write("mag_world_ut: [1, 2]\n");
  EXPECT_THROW(load_vehicle_params(path), std::runtime_error);
  write("mode: ekf\nswitching:\n  static_speed_max_mps: 1.5\n");
  const VehicleParams p = load_vehicle_params(path);
  EXPECT_EQ(p.mode, VehicleMode::kEkf);
  EXPECT_DOUBLE_EQ(p.static_speed_max_mps, 1.5);
  VehicleParams bad;
  bad.r_mag_ut2.y() = 0.0;
  EXPECT_THROW(VehicleEstimator{bad}, std::invalid_argument);
}

// The IMU's body axes are the vehicle's: a_x, a_y = accel x, y; r = gyro z.
TEST(VehicleSampleFromImu, TakesTheVehicleAxesAndTheSpeedInput) {
  ImuSample imu;
  imu.stamp_ns = 5;
  imu.accel_mps2 = Eigen::Vector3d(1, 2, 3);
  imu.gyro_rps = Eigen::Vector3d(4, 5, 6);
  imu.mag_ut = Eigen::Vector3d(7, 8, 9);
  imu.has_mag = false;
  const VehicleSample v = vehicle_sample_from_imu(imu, true, 12.5);
  EXPECT_EQ(v.stamp_ns, 5);
  EXPECT_EQ(v.accel_lon_mps2, 1.0);
  EXPECT_EQ(v.accel_lat_mps2, 2.0);
  EXPECT_EQ(v.yaw_rate_rps, 6.0);
  EXPECT_EQ(v.mag_ut, Eigen::Vector3d(7, 8, 9));
  EXPECT_FALSE(v.has_mag);
  EXPECT_TRUE(v.has_speed);
  EXPECT_EQ(v.speed_mps, 12.5);
}

// The core says what it did with the magnetometer and the speed (the node only maps it).
TEST(VehicleSources, DisturbedMagAndBadSpeedAreReportedRejected) {
  VehicleEstimator est;
  VehicleSample s;
  s.stamp_ns = 1'000'000'000;
  s.accel_lat_mps2 = 0.0;
  s.mag_ut = VehicleParams{}.mag_world_ut;
  s.has_mag = true;
  s.speed_mps = 0.0;
  ASSERT_TRUE(est.update(s));
  SourceReports r = est.sources();
  ASSERT_EQ(r.size(), 4U);
  EXPECT_EQ(r[2].source, Source::kMag);
  EXPECT_EQ(r[2].decision, SourceDecision::kFused);
  EXPECT_EQ(r[3].decision, SourceDecision::kFused);
  s.stamp_ns += kStepNs;
  s.mag_ut *= 2.0;  // |B| = 2 |H|: outside (1 +- 0.5) |H|
  s.speed_mps = -1.0;
  ASSERT_TRUE(est.update(s));
  r = est.sources();
  EXPECT_EQ(r[2].decision, SourceDecision::kRejected);
  EXPECT_STREQ(r[2].reason, "disturbed_mag");
  EXPECT_NEAR(r[2].test_ratio, 4.0, 1e-9) << "(|H| / (0.5 |H|))^2";
  EXPECT_EQ(r[3].decision, SourceDecision::kRejected);
  EXPECT_STREQ(r[3].reason, "bad_speed");
  s.stamp_ns += kStepNs;
  s.has_mag = false;
  s.has_speed = false;
  ASSERT_TRUE(est.update(s));
  r = est.sources();
  EXPECT_EQ(r[2].decision, SourceDecision::kNotAvailable);
  EXPECT_EQ(r[3].decision, SourceDecision::kNotAvailable);
}

std::string fingerprint(const VehicleEstimator& est) {
  const VehicleEstimate& e = est.estimate();
  const VehicleRejects& r = est.rejects();
  testing::Fingerprint p;
  p.add(e.stamp_ns).add(e.roll_rad).add(e.pitch_rad).add(e.yaw_rad).add(e.q_world_body.coeffs());
  p.add(e.is_static).add(e.from_triad).add(e.valid).add(est.ekf_state()).add(est.ekf_covariance());
  p.add(est.ekf_initialized()).add(est.sources()).add(r.samples).add(r.bad_speed).add(r.missing_mag);
  p.add(r.disturbed_mag).add(est.state_resets());
  return p.str();
}

TEST(VehicleEstimator, GivenAStateTakenMidRunWhenRestoredThenTheSameSamplesGiveBitIdenticalOutputsAndReports) {
  // GIVEN an estimator 5 s into a steady 0.1 rad/s turn at 20 m/s (EKF running)
  const auto sample = [](int k) {
    const double t = k * 0.01;
    VehicleSample s = static_sample(k * kStepNs, 0.0, 0.0, 0.8 + 0.1 * t);
    s.yaw_rate_rps = 0.1;
    s.speed_mps = k < 100 ? 0.0 : 20.0;  // standstill first (TRIAD), then driving (EKF)
    return s;
  };
  VehicleEstimator a;
  int k = 0;
  for (; k < 500; ++k) {
    ASSERT_TRUE(a.update(sample(k)));
  }
  std::vector<VehicleSample> next;  // the next 20 s, one speed refused
  for (; k < 2500; ++k) {
    next.push_back(sample(k));
  }
  next[500].speed_mps = -1.0;
  // WHEN they run, then run again from the state taken before them (in a new estimator and in the
  // same one) and after reset() next to a new estimator, THEN every output, report and counter is the
  // same bit for bit: state() holds everything
  testing::expect_state_round_trips(a, next, [] { return VehicleEstimator(); }, fingerprint);
}

// One validation shape (ParamCheck): a bad value of a key is an error at construction that names
// the key as in the YAML file and its range/unit, never a silent repair or a NaN later.
TEST(VehicleParams, GivenABadValueOfAKeyWhenTheFilterIsBuiltThenTheErrorNamesTheKey) {
  testing::expect_bad_values_name_their_keys<VehicleParams>("vehicle", VehicleParams{}, {
    {"model.m_s_kg", [](VehicleParams& p) { p.model.m_s_kg = 0.0; }},
    {"mag_world_ut", [](VehicleParams& p) { p.mag_world_ut = Eigen::Vector3d(0.0, 0.0, -40.0); }},
    {"ekf.r_mag_ut2", [](VehicleParams& p) { p.r_mag_ut2.y() = 0.0; }},
    {"mag_norm_tolerance", [](VehicleParams& p) { p.mag_norm_tolerance = 1.0; }}
  }, [](const VehicleParams& p) { VehicleEstimator f(p); });
}

}  // namespace
}  // namespace poise

namespace poise {
namespace {

// State health (issue 19): a non-finite EKF state or a covariance with a NaN or that is not
// positive semi-definite (through set_state(): no sample that passes the input checks gets there)
// resets the estimator on the next update, counted, nothing non-finite comes out, and it
// re-converges. EKF mode (the switched mode re-initialises from TRIAD at every static sample).
// Oracle: an estimator that was never spoilt, on the same samples.
TEST(VehicleEstimator, GivenAnUnhealthyStateWhenUpdatedThenTheEstimatorResetsCountsItAndReconverges) {
  constexpr double kSameAsCleanRad = 1e-4;  // 7 s after the reset (noiseless static samples)
  constexpr double kRoll = 0.1;
  constexpr double kYaw = 0.5;
  struct Case {
    const char* name;
    void (*spoil)(VehicleEstimatorState&);
  };
  const Case cases[] = {
      {"NaN yaw", [](VehicleEstimatorState& st) { st.x(4) = std::nan(""); }},
      {"NaN covariance entry", [](VehicleEstimatorState& st) { st.p(2, 2) = std::nan(""); }},
      {"indefinite covariance",  // positive diagonal: found by the periodic LDLT check
       [](VehicleEstimatorState& st) { st.p(0, 4) = st.p(4, 0) = 10.0 * std::max(st.p(0, 0), 1e-6); }},
  };
  for (const Case& c : cases) {
    VehicleParams p;
    p.mode = VehicleMode::kEkf;
    VehicleEstimator e(p);
    VehicleEstimator clean(p);
    for (int k = 0; k < 1500; ++k) {
      clean.update(static_sample(k * kStepNs, kRoll, 0.0, kYaw));
      if (k == 300) {
        VehicleEstimatorState st = e.state();
        c.spoil(st);
        e.set_state(st);
      }
      const uint64_t resets_before = e.state_resets();
      const bool used = e.update(static_sample(k * kStepNs, kRoll, 0.0, kYaw));
      if (e.state_resets() != resets_before) {  // the resetting update: refused, not initialised
        EXPECT_FALSE(used) << c.name;
        EXPECT_FALSE(e.estimate().valid) << c.name;
        EXPECT_STREQ(e.sources()[0].reason, kStateResetReason) << c.name;
      }
      ASSERT_TRUE(e.estimate().q_world_body.coeffs().allFinite()) << c.name << " at " << k;
    }
    EXPECT_EQ(e.state_resets(), 1u) << c.name;
    EXPECT_EQ(e.rejects().samples.total(), 0u) << c.name;
    EXPECT_TRUE(e.estimate().valid) << c.name;
    std::printf("%s: roll %.6f (clean %.6f), yaw %.6f (clean %.6f) rad\n", c.name, e.estimate().roll_rad,
                clean.estimate().roll_rad, e.estimate().yaw_rad, clean.estimate().yaw_rad);
    EXPECT_NEAR(e.estimate().roll_rad, clean.estimate().roll_rad, kSameAsCleanRad) << c.name;
    EXPECT_NEAR(e.estimate().pitch_rad, clean.estimate().pitch_rad, kSameAsCleanRad) << c.name;
    EXPECT_NEAR(e.estimate().yaw_rad, clean.estimate().yaw_rad, kSameAsCleanRad) << c.name;
  }
}

}  // namespace
}  // namespace poise
