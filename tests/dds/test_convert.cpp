// Pure conversions between core types and IDL messages.
#include "poise/dds/convert.h"
#include "poise/dds/topics.h"

#include <gtest/gtest.h>

namespace poise::dds {
namespace {

TEST(Convert, ImuSampleRoundTripKeepsEveryField) {
  ImuSample s;
  s.stamp_ns = 123456789012345;
  s.seq = 42;
  s.accel_mps2 = {0.1, -9.7, 9.81};
  s.gyro_rps = {0.01, 0.02, -0.03};
  s.mag_ut = {20.5, -3.25, -40.0};
  s.pressure_pa = 101325.5;
  s.temperature_c = 24.5;
  s.has_mag = false;
  s.has_pressure = true;
  s.has_temperature = true;
  const msg::ImuSample m = to_msg(s, "imu0");
  EXPECT_EQ(m.sensor_id(), "imu0");
  EXPECT_EQ(m.header().frame_id(), "body");
  EXPECT_EQ(m.header().stamp_ns(), s.stamp_ns);
  EXPECT_FALSE(m.valid().mag());
  const ImuSample back = from_msg(m);
  EXPECT_EQ(back.stamp_ns, s.stamp_ns);
  EXPECT_EQ(back.seq, s.seq);
  EXPECT_EQ(back.accel_mps2, s.accel_mps2);
  EXPECT_EQ(back.gyro_rps, s.gyro_rps);
  EXPECT_EQ(back.mag_ut, s.mag_ut);
  EXPECT_EQ(back.pressure_pa, s.pressure_pa);
  EXPECT_EQ(back.temperature_c, s.temperature_c);
  EXPECT_EQ(back.has_accel, s.has_accel);
  EXPECT_EQ(back.has_gyro, s.has_gyro);
  EXPECT_EQ(back.has_mag, s.has_mag);
  EXPECT_EQ(back.has_pressure, s.has_pressure);
  EXPECT_EQ(back.has_temperature, s.has_temperature);
}

TEST(Convert, QuaternionIsStoredWxyz) {
  const Eigen::Quaterniond q(0.5, -0.5, 0.5, 0.5);  // Eigen's constructor takes (w, x, y, z)
  const msg::Quaternion m = to_msg(q);
  EXPECT_EQ(m.w(), 0.5);
  EXPECT_EQ(m.x(), -0.5);
  EXPECT_EQ(m.y(), 0.5);
  EXPECT_EQ(m.z(), 0.5);
  EXPECT_TRUE(from_msg(m).coeffs().isApprox(q.coeffs(), 0.0));
}

TEST(Convert, MatrixArraysAreRowMajor) {
  Eigen::Matrix<double, 2, 3> m;
  m << 1, 2, 3, 4, 5, 6;
  std::array<double, 6> a{};
  to_array(m, a);
  EXPECT_EQ(a, (std::array<double, 6>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ((from_array<2, 3>(a)), m);
}

// The body pose only when the camera had an extrinsic; never the camera pose in its place.
TEST(Convert, VisionPoseBodyOnlyWhenValidCameraAlways) {
  msg::VisionPose v;
  v.capture_stamp_ns(77);
  msg::Pose camera;
  camera.position_m(to_msg(Eigen::Vector3d(1, 2, 3)));
  camera.orientation(to_msg(Eigen::Quaterniond(1, 0, 0, 0)));
  msg::Pose body;
  body.position_m(to_msg(Eigen::Vector3d(4, 5, 6)));
  body.orientation(to_msg(Eigen::Quaterniond(0, 1, 0, 0)));
  v.pose_world_camera(camera);
  v.pose_world_body(body);
  v.covariance()[0] = 0.01;
  v.body_valid(true);
  const std::optional<PoseMeasurement> body_pose = body_pose_from_msg(v);
  ASSERT_TRUE(body_pose.has_value());
  EXPECT_EQ(body_pose->p_world_body_m, Eigen::Vector3d(4, 5, 6));
  EXPECT_EQ(body_pose->q_world_body.coeffs(), Eigen::Quaterniond(0, 1, 0, 0).coeffs());
  EXPECT_EQ(body_pose->stamp_ns, 77);
  EXPECT_EQ(body_pose->covariance(0, 0), 0.01);
  v.body_valid(false);
  EXPECT_FALSE(body_pose_from_msg(v).has_value()) << "no extrinsic: a rejection, not the camera pose";
  const CameraPoseMeasurement camera_pose = camera_pose_from_msg(v);
  EXPECT_EQ(camera_pose.p_world_camera_m, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(camera_pose.q_world_camera.coeffs(), Eigen::Quaterniond(1, 0, 0, 0).coeffs());
  EXPECT_EQ(camera_pose.stamp_ns, 77);
  EXPECT_EQ(camera_pose.covariance(0, 0), 0.01);
}

TEST(Convert, FiniteChecksCatchNan) {
  msg::Vector3 v = to_msg(Eigen::Vector3d(1, 2, 3));
  EXPECT_TRUE(is_finite(v));
  v.y(std::numeric_limits<double>::quiet_NaN());
  EXPECT_FALSE(is_finite(v));
}

TEST(Topics, DefaultNamesAndQosKinds) {
  const TopicNames names;
  EXPECT_EQ(names.attitude("parallel_kf"), "attitude/parallel_kf");
  EXPECT_EQ(names.pose("selective_ekf"), "pose/selective_ekf");
  EXPECT_EQ(default_qos_for_topic("imu"), QosKind::kSensor);
  EXPECT_EQ(default_qos_for_topic("tag_detections"), QosKind::kSensor);
  EXPECT_EQ(default_qos_for_topic("attitude/parallel_kf"), QosKind::kEstimate);
  EXPECT_EQ(default_qos_for_topic("diagnostics"), QosKind::kEstimate);
  EXPECT_STREQ(profile_name(QosKind::kStatic), "static");
}

}  // namespace
}  // namespace poise::dds
