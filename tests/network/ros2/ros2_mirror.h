// Mirrors of poise messages in ROS 2 layouts (idl/ros2): sensor_msgs/Imu from ImuSample and
// geometry_msgs/PoseWithCovarianceStamped from PoseEstimate, for topics `rt/<name>` that ROS 2
// tools read. Pure conversions (no DDS entities, no clocks): the caller passes the offset that maps
// poise stamps (host CLOCK_MONOTONIC) onto ROS time (CLOCK_REALTIME).
#pragma once

#include <poise/msg/estimates.h>
#include <poise/msg/imu.h>
#include <poise/ros2/geometry_msgs.h>
#include <poise/ros2/sensor_msgs.h>

#include <cstdint>

namespace poise::nettest::ros2 {

namespace ros_msg = ::sensor_msgs::msg::dds_;
namespace ros_geo = ::geometry_msgs::msg::dds_;

/// ROS Time {sec, nanosec} of `stamp_ns + offset_ns` (floor division: nanosec in [0, 1e9)).
::builtin_interfaces::msg::dds_::Time_ to_ros_time(int64_t stamp_ns, int64_t offset_ns);

/// sensor_msgs/Imu: angular_velocity = gyro_rps, linear_acceleration = accel_mps2 (specific force,
/// as ROS expects), frame_id kept. No orientation (REP 145: orientation_covariance[0] = -1);
/// channels flagged invalid get covariance[0] = -1; unknown covariances are all zeros.
ros_msg::Imu_ to_ros_imu(const msg::ImuSample& in, int64_t offset_ns);

/// geometry_msgs/PoseWithCovarianceStamped: position, orientation (x, y, z, w order), covariance
/// 6x6 [x y z rx ry rz] taken from poise's 9x9 [p v theta] (position and attitude blocks and their
/// cross terms). ENU world = ROS REP 103 map/odom convention.
ros_geo::PoseWithCovarianceStamped_ to_ros_pose(const msg::PoseEstimate& in, int64_t offset_ns);

}  // namespace poise::nettest::ros2
