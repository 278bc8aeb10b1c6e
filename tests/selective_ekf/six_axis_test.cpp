// Issue 20, 6-axis input: without a magnetometer every attitude filter starts from the same
// stated attitude, the accelerometer's tilt with ZYX yaw 0 (quat_tilt_yaw0). Oracle: the tilted
// static sensor's true roll and pitch, yaw 0 by the convention.
#include "poise/core/attitude.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/selective_ekf/selective_ekf.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace poise
