// Issue 20, 6-axis input: without a magnetometer every attitude filter starts from the same
// stated attitude, the accelerometer's tilt with ZYX yaw 0 (quat_tilt_yaw0). Oracle: the tilted
// static sensor's true roll and pitch, yaw 0 by the convention.
#include "poise/core/attitude.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/vehicle/vehicle_estimator.h"

#include <gtest/gtest.h>

#include <fstream>
#include <functional>
#include <string>

namespace poise {
namespace {

constexpr double kRollRad = 20.0 * kRadPerDeg;
constexpr double kPitchRad = -10.0 * kRadPerDeg;
constexpr double kAngleTolRad = 1e-6;   // a static, noise-free sensor: the tilt is exact
constexpr double kTiltTolRad = 0.2 * kRadPerDeg;  // after the filters' start-up transients

std::vector<ImuSample> six_axis_static(int n) {
  const Eigen::Quaterniond q = quat_from_euler_zyx(kRollRad, kPitchRad, 1.0);  // true yaw: unobservable
  std::vector<ImuSample> out;
  for (int k = 0; k < n; ++k) {
    ImuSample s;
    s.stamp_ns = 1'000'000'000 + int64_t{k} * 10'000'000;  // 100 Hz
    s.seq = static_cast<uint32_t>(k);
    s.accel_mps2 = q.conjugate() * Eigen::Vector3d(0, 0, kStandardGravityMps2);
    s.gyro_rps.setZero();
    s.has_mag = false;
    out.push_back(s);
  }
  return out;
}

TEST(SixAxis, WithoutAMagnetometerEveryFilterStartsAtTheSameStatedYawZero) {
  const Eigen::Quaterniond stated = quat_tilt_yaw0(six_axis_static(1).front().accel_mps2);
  const Eigen::Vector3d e = euler_zyx_from_quat(stated);
  EXPECT_NEAR(e.x(), kRollRad, kAngleTolRad);
  EXPECT_NEAR(e.y(), kPitchRad, kAngleTolRad);
  EXPECT_NEAR(e.z(), 0.0, kAngleTolRad);

  ParallelKf pkf;
  SelectiveEkfFilter ekf;
  const std::vector<ImuSample> samples = six_axis_static(300);
  ASSERT_TRUE(pkf.update(samples.front()));
  ASSERT_TRUE(ekf.update(samples.front()));
  // the first estimates: the stated start, in both
  EXPECT_LT(quat_angle_between(pkf.q_world_body(), stated), kAngleTolRad);
  EXPECT_LT(quat_angle_between(ekf.q_world_body(), stated), kAngleTolRad);
  for (std::size_t k = 1; k < samples.size(); ++k) {
    pkf.update(samples[k]);
    ekf.update(samples[k]);
  }
  // 3 s later, still at rest: yaw stays 0 in both (no field, no gyro rate), the tilt is right
  for (const Eigen::Quaterniond& q : {pkf.q_world_body(), ekf.q_world_body()}) {
    const Eigen::Vector3d f = euler_zyx_from_quat(q);
    EXPECT_NEAR(f.z(), 0.0, kTiltTolRad);
    EXPECT_NEAR(f.x(), kRollRad, kTiltTolRad);
    EXPECT_NEAR(f.y(), kPitchRad, kTiltTolRad);
  }
}


// A 6-axis sensor tilted by (kRollRad, kPitchRad), at rest for kRestS, then turned about the
// vertical at kTurnRateRps for kTurnS; no gyro bias, no noise. Oracle: its true attitude
// q(t) = Rz(psi(t)) q_tilt with psi(t) = kTurnRateRps (t - kRestS), whose ZYX yaw is psi(t).
constexpr double kTurnRateRps = 30.0 * kRadPerDeg;
constexpr double kRestS = 1.0;
constexpr double kTurnS = 3.0;
constexpr double kRateHz = 100.0;
// Tolerances: the heading integrated from an exact gyro by each filter's propagation (exact
// rotation, trapezoidal in the parallel KF) against the analytic yaw, and the two filters' yaws
// against each other (both start at yaw 0 and integrate the same rate).
constexpr double kYawFollowTolDeg = 0.5;
constexpr double kFiltersAgreeTolDeg = 0.5;

struct TurnSample {
  ImuSample imu;
  Eigen::Quaterniond truth;
  double yaw_rad = 0.0;  // analytic
};

std::vector<TurnSample> six_axis_turn() {
  const Eigen::Quaterniond tilt = quat_from_euler_zyx(kRollRad, kPitchRad, 0.0);
  const int n = static_cast<int>((kRestS + kTurnS) * kRateHz) + 1;
  std::vector<TurnSample> out;
  for (int k = 0; k < n; ++k) {
    const double t = k / kRateHz;
    TurnSample s;
    // The gyro over (k-1, k] is the constant rate once turning started: sampled at k it is the
    // rate of the interval ending at k (the first turning sample's interval is all turning).
    const bool turning = t > kRestS + 1e-9;
    s.yaw_rad = turning ? kTurnRateRps * (t - kRestS) : 0.0;
    s.truth = Eigen::Quaterniond(Eigen::AngleAxisd(s.yaw_rad, Eigen::Vector3d::UnitZ())) * tilt;
    s.imu.stamp_ns = 1'000'000'000 + int64_t{k} * 10'000'000;
    s.imu.seq = static_cast<uint32_t>(k);
    s.imu.accel_mps2 = s.truth.conjugate() * Eigen::Vector3d(0, 0, kStandardGravityMps2);
    s.imu.gyro_rps = turning ? Eigen::Vector3d(s.truth.conjugate() * Eigen::Vector3d(0, 0, kTurnRateRps))
                             : Eigen::Vector3d::Zero();
    // has_mag stays false: the default, a 6-axis source says nothing about a magnetometer
    out.push_back(s);
  }
  return out;
}

double yaw_deg(const Eigen::Quaterniond& q) { return euler_zyx_from_quat(q).z() / kRadPerDeg; }
double wrap_deg(double d) { return std::remainder(d, 360.0); }

TEST(SixAxis, ASampleHasAMagnetometerOnlyWhenItsSourceSaysSo) {
  EXPECT_FALSE(ImuSample{}.has_mag);
  EXPECT_FALSE(VehicleSample{}.has_mag);
  EXPECT_EQ(ParallelKfParams{}.use_magnetometer, MagnetometerUse::kAuto);
  EXPECT_EQ(SelectiveEkfParams{}.use_magnetometer, MagnetometerUse::kAuto);
  EXPECT_EQ(GaussNewtonParams{}.use_magnetometer, MagnetometerUse::kAuto);
  EXPECT_EQ(VehicleParams{}.use_magnetometer, MagnetometerUse::kAuto);
}

TEST(SixAxis, GivenATurnAboutTheVerticalWithoutAMagnetometerThenTheParallelKfsHeadingFollowsTheGyro) {
  const std::vector<TurnSample> samples = six_axis_turn();
  ParallelKf pkf;
  SelectiveEkfFilter ekf;
  double worst_pkf_deg = 0.0;
  double worst_ekf_deg = 0.0;
  double worst_agree_deg = 0.0;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    ASSERT_TRUE(pkf.update(samples[k].imu)) << k;
    ASSERT_TRUE(ekf.update(samples[k].imu)) << k;
    if (k == 0) {  // both start at the stated yaw 0
      EXPECT_NEAR(yaw_deg(pkf.q_world_body()), 0.0, kAngleTolRad / kRadPerDeg);
      EXPECT_NEAR(yaw_deg(ekf.q_world_body()), 0.0, kAngleTolRad / kRadPerDeg);
    }
    const double truth_deg = samples[k].yaw_rad / kRadPerDeg;
    worst_pkf_deg = std::max(worst_pkf_deg, std::abs(wrap_deg(yaw_deg(pkf.q_world_body()) - truth_deg)));
    worst_ekf_deg = std::max(worst_ekf_deg, std::abs(wrap_deg(yaw_deg(ekf.q_world_body()) - truth_deg)));
    worst_agree_deg = std::max(
        worst_agree_deg, std::abs(wrap_deg(yaw_deg(pkf.q_world_body()) - yaw_deg(ekf.q_world_body()))));
  }
  std::printf("6-axis turn, 30 deg/s for 3 s: largest yaw error parallel KF %.4f deg, selective EKF %.4f deg, "
              "between them %.4f deg\n", worst_pkf_deg, worst_ekf_deg, worst_agree_deg);
  EXPECT_LT(worst_pkf_deg, kYawFollowTolDeg);
  EXPECT_LT(worst_ekf_deg, kYawFollowTolDeg);
  EXPECT_LT(worst_agree_deg, kFiltersAgreeTolDeg);
  // the turn really happened: 90 deg at the end, and the whole attitude (tilt too) is right
  EXPECT_NEAR(samples.back().yaw_rad / kRadPerDeg, 90.0, 1e-9);
  EXPECT_LT(quat_angle_between(pkf.q_world_body(), samples.back().truth) / kRadPerDeg, kYawFollowTolDeg);
  // heading not observable: the magnetometer source says why
  EXPECT_EQ(pkf.sources()[2].decision, SourceDecision::kNotAvailable);
  EXPECT_STREQ(pkf.sources()[2].reason, "no_sample");
  EXPECT_EQ(pkf.rejections().total(), 0U);
}

// 9-axis samples of the same turn: the field points 40 deg away from the 6-axis start.
std::vector<TurnSample> nine_axis_turn() {
  std::vector<TurnSample> out = six_axis_turn();
  const Eigen::Vector3d field_world =
      Eigen::AngleAxisd(40.0 * kRadPerDeg, Eigen::Vector3d::UnitZ()) * Eigen::Vector3d(0.0, 20.0, -40.0);
  for (TurnSample& s : out) {
    s.imu.mag_ut = s.truth.conjugate() * field_world;
    s.imu.has_mag = true;
  }
  return out;
}

TEST(SixAxis, GivenUseMagnetometerFalseThenANineAxisInputRunsExactlyAsSixAxis) {
  const std::vector<TurnSample> nine = nine_axis_turn();
  const std::vector<TurnSample> six = six_axis_turn();
  ParallelKfParams off;
  off.use_magnetometer = MagnetometerUse::kOff;
  ParallelKf pkf_off(off);
  ParallelKf pkf_six;  // oracle: the same motion told it has no magnetometer
  SelectiveEkfParams eoff;
  eoff.use_magnetometer = MagnetometerUse::kOff;
  SelectiveEkf ekf_off(eoff);
  SelectiveEkf ekf_six;
  ParallelKf pkf_auto;  // and with auto the field is used: heading 40 deg away from the 6-axis one
  for (std::size_t k = 0; k < nine.size(); ++k) {
    ASSERT_TRUE(pkf_off.update(nine[k].imu));
    ASSERT_TRUE(pkf_six.update(six[k].imu));
    ASSERT_TRUE(ekf_off.update_imu(nine[k].imu));
    ASSERT_TRUE(ekf_six.update_imu(six[k].imu));
    pkf_auto.update(nine[k].imu);
    ASSERT_EQ(pkf_off.q_world_body().coeffs(), pkf_six.q_world_body().coeffs()) << k;
    ASSERT_EQ(ekf_off.q_world_body().coeffs(), ekf_six.q_world_body().coeffs()) << k;
  }
  EXPECT_EQ(pkf_off.rejections().total(), 0U) << "a switched-off magnetometer is neither checked nor counted";
  EXPECT_EQ(pkf_off.sources()[2].decision, SourceDecision::kNotAvailable);
  EXPECT_STREQ(pkf_off.sources()[2].reason, "use_magnetometer_false");
  EXPECT_GT(std::abs(wrap_deg(yaw_deg(pkf_auto.q_world_body()) - yaw_deg(pkf_off.q_world_body()))), 30.0);
}

TEST(SixAxis, GivenUseMagnetometerTrueThenSamplesWithoutOneAreRefusedCountedAndReported) {
  const std::vector<TurnSample> nine = nine_axis_turn();
  const std::vector<TurnSample> six = six_axis_turn();
  ParallelKfParams pp;
  pp.use_magnetometer = MagnetometerUse::kRequired;
  SelectiveEkfParams ep;
  ep.use_magnetometer = MagnetometerUse::kRequired;
  GaussNewtonParams gp;
  gp.use_magnetometer = MagnetometerUse::kRequired;
  VehicleParams vp;
  vp.use_magnetometer = MagnetometerUse::kRequired;
  ParallelKf pkf(pp);
  SelectiveEkf ekf(ep);
  GaussNewton gn(gp);
  VehicleEstimator veh(vp);
  constexpr std::size_t kWithout = 10;  // every 10th sample of 401 has no magnetometer
  std::size_t without = 0;
  for (std::size_t k = 0; k < nine.size(); ++k) {
    const bool has = k % kWithout != 5;
    const ImuSample& s = has ? nine[k].imu : six[k].imu;
    without += has ? 0 : 1;
    EXPECT_EQ(pkf.update(s), has) << k;
    EXPECT_EQ(ekf.update_imu(s), has) << k;
    EXPECT_EQ(gn.update(s), has) << k;
    EXPECT_EQ(veh.update(vehicle_sample_from_imu(s, true, 0.0)), has) << k;
    if (!has) {
      for (const SourceReport& r : pkf.sources()) {
        EXPECT_EQ(r.decision, SourceDecision::kRejected);
        EXPECT_STREQ(r.reason, "no_magnetometer");
      }
    }
  }
  ASSERT_EQ(without, 40U);
  EXPECT_EQ(pkf.rejections().count(RejectReason::kNoMagnetometer), without);
  EXPECT_EQ(ekf.imu_rejections().count(RejectReason::kNoMagnetometer), without);
  EXPECT_EQ(gn.rejections().count(RejectReason::kNoMagnetometer), without);
  EXPECT_EQ(veh.rejects().samples.count(RejectReason::kNoMagnetometer), without);
  EXPECT_EQ(pkf.rejections().to_map().at("no_magnetometer"), without);
}

std::string write_temp(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

std::string load_error(const std::function<void()>& load) {
  try {
    load();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(SixAxis, UseMagnetometerIsReadAsAutoTrueOrFalseByEveryAttitudeFiltersLoaderAndAnythingElseIsRefused) {
  struct Loader {
    const char* name;
    std::string prefix;  // the section the key sits in
    std::function<MagnetometerUse(const std::string&)> load;
  };
  const std::vector<Loader> loaders{
      {"parallel_kf", "parallel_kf:\n  ", [](const std::string& p) { return load_parallel_kf_params(p).use_magnetometer; }},
      {"selective_ekf", "selective_ekf:\n  ",
       [](const std::string& p) { return load_selective_ekf_params(p).use_magnetometer; }},
      {"gauss_newton", "", [](const std::string& p) { return load_gauss_newton_params(p).use_magnetometer; }},
      {"vehicle", "", [](const std::string& p) { return load_vehicle_params(p).use_magnetometer; }},
  };
  for (const Loader& l : loaders) {
    SCOPED_TRACE(l.name);
    const std::string stem = std::string("use_mag_") + l.name;
    EXPECT_EQ(l.load(write_temp(stem + "_auto.yaml", l.prefix + "use_magnetometer: auto\n")), MagnetometerUse::kAuto);
    EXPECT_EQ(l.load(write_temp(stem + "_true.yaml", l.prefix + "use_magnetometer: true\n")),
              MagnetometerUse::kRequired);
    if (std::string(l.name) == "gauss_newton") {
      const std::string e = load_error([&] { l.load(write_temp(stem + "_false.yaml", "use_magnetometer: false\n")); });
      EXPECT_NE(e.find("use_magnetometer"), std::string::npos) << e;
      EXPECT_NE(e.find("needs the magnetometer"), std::string::npos) << e;
    } else {
      EXPECT_EQ(l.load(write_temp(stem + "_false.yaml", l.prefix + "use_magnetometer: false\n")),
                MagnetometerUse::kOff);
    }
    for (const char* bad : {"yes", "maybe", "1", "[true]"}) {
      SCOPED_TRACE(bad);
      const std::string path = write_temp(stem + "_bad.yaml", l.prefix + "use_magnetometer: " + bad + "\n");
      const std::string e = load_error([&] { l.load(path); });
      EXPECT_NE(e.find(path), std::string::npos) << e;
      EXPECT_NE(e.find("use_magnetometer"), std::string::npos) << e;
      EXPECT_NE(e.find("auto, true or false"), std::string::npos) << e;
    }
  }
}

}  // namespace
}  // namespace poise
