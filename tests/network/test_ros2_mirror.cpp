// The ROS 2 mirror conversions (ros2/ros2_mirror.h): field order, units, REP 145 conventions and
// the 9x9 -> 6x6 covariance re-layout, with explicit oracles.
#include "net_samples.h"
#include "ros2_mirror.h"

#include <gtest/gtest.h>

namespace poise::nettest::ros2 {
namespace {

TEST(Ros2Mirror, TimeSplitsIntoSecondsAndNanosecondsWithOffset) {
  const auto t = to_ros_time(1'500'000'123LL, 1'700'000'000'000'000'000LL);
  EXPECT_EQ(t.sec(), 1'700'000'001);
  EXPECT_EQ(t.nanosec(), 500'000'123U);
  const auto negative = to_ros_time(-1, 0);  // floor division: -1 ns = -1 s + 999999999 ns
  EXPECT_EQ(negative.sec(), -1);
  EXPECT_EQ(negative.nanosec(), 999'999'999U);
}

TEST(Ros2Mirror, ImuKeepsGyroAndSpecificForceAndFlagsNoOrientation) {
  msg::ImuSample in;
  in.header().stamp_ns(42);
  in.header().frame_id("body");
  in.gyro_rps().x(0.1);
  in.gyro_rps().y(-0.2);
  in.gyro_rps().z(0.3);
  in.accel_mps2().x(0.5);
  in.accel_mps2().y(-0.25);
  in.accel_mps2().z(9.80665);
  in.valid().gyro(true);
  in.valid().accel(false);
  const auto out = to_ros_imu(in, 0);
  EXPECT_EQ(out.header().frame_id(), "body");
  EXPECT_EQ(out.header().stamp().nanosec(), 42U);
  EXPECT_EQ(out.angular_velocity().x(), 0.1);
  EXPECT_EQ(out.angular_velocity().y(), -0.2);
  EXPECT_EQ(out.angular_velocity().z(), 0.3);
  EXPECT_EQ(out.linear_acceleration().z(), 9.80665) << "specific force, +g up at rest (ROS too)";
  EXPECT_EQ(out.orientation_covariance()[0], -1.0) << "REP 145: no orientation";
  EXPECT_EQ(out.angular_velocity_covariance()[0], 0.0) << "valid, covariance unknown";
  EXPECT_EQ(out.linear_acceleration_covariance()[0], -1.0) << "accel flagged invalid";
}

TEST(Ros2Mirror, PoseReordersQuaternionAndTakesPositionAndAttitudeCovarianceBlocks) {
  msg::PoseEstimate in;
  in.header().frame_id("world");
  in.position_m().x(1.0);
  in.q_world_body().w(0.1);
  in.q_world_body().x(0.2);
  in.q_world_body().y(0.3);
  in.q_world_body().z(0.4);
  for (size_t r = 0; r < 9; ++r) {
    for (size_t c = 0; c < 9; ++c) {
      in.covariance()[r * 9 + c] = pose_covariance(r, c);
    }
  }
  const auto out = to_ros_pose(in, 0);
  EXPECT_EQ(out.pose().pose().orientation().x(), 0.2);
  EXPECT_EQ(out.pose().pose().orientation().w(), 0.1) << "ROS order is x, y, z, w";
  const auto& cov = out.pose().covariance();
  EXPECT_EQ(cov[0 * 6 + 0], pose_covariance(0, 0));  // x x
  EXPECT_EQ(cov[2 * 6 + 2], pose_covariance(2, 2));  // z z
  EXPECT_EQ(cov[3 * 6 + 3], pose_covariance(6, 6));  // roll-axis: theta_x
  EXPECT_EQ(cov[5 * 6 + 5], pose_covariance(8, 8));  // theta_z
  EXPECT_EQ(cov[0 * 6 + 4], pose_covariance(0, 7));  // x with theta_y
  EXPECT_EQ(cov[4 * 6 + 1], pose_covariance(7, 1));  // theta_y with y
  for (double v : cov) {
    const auto row = static_cast<size_t>(v - 1.0) / 100;
    EXPECT_TRUE(row < 3 || row >= 6) << "no velocity rows in the pose covariance: " << v;
  }
}

}  // namespace
}  // namespace poise::nettest::ros2
