// Pure conversions between poise messages and the ROS 2 message types of idl/ros2 (no DDS
// entities, no clocks): what the `ros2_bridge` component publishes and reads (docs/ROS2.md).
//
// Conventions kept: ENU world (REP 103) and the body's own axes, quaternions reordered
// (poise w,x,y,z -> ROS x,y,z,w), SI units (ROS magnetic field in tesla, poise in microtesla),
// covariances per REP 145 (element 0 = -1: the part is absent; all zeros: present, covariance
// unknown), header.stamp = stamp_ns + offset_ns (offset 0: the sensor clock itself).
#pragma once

#include "poise/core/types.h"

#include <poise/msg/estimates.h>
#include <poise/msg/imu.h>
#include <poise/ros2/diagnostic_msgs.h>
#include <poise/ros2/nav_msgs.h>
#include <poise/ros2/sensor_msgs.h>
#include <poise/ros2/tf2_msgs.h>

#include <array>
#include <cstdint>
#include <optional>
#include <string>

namespace poise::ros2 {

namespace ros_time = ::builtin_interfaces::msg::dds_;
namespace ros_geo = ::geometry_msgs::msg::dds_;
namespace ros_sensor = ::sensor_msgs::msg::dds_;
namespace ros_nav = ::nav_msgs::msg::dds_;
namespace ros_tf = ::tf2_msgs::msg::dds_;
namespace ros_diag = ::diagnostic_msgs::msg::dds_;

/// Frame ids of the bridged messages.
struct Frames {
  std::string world = "world";    ///< ENU world: header.frame_id of estimates, tf parent
  std::string body = "imu_link";  ///< the IMU's axes: raw IMU frame_id, odometry/tf child
};

/// ROS Time of `stamp_ns + offset_ns` (floor division: nanosec in [0, 1e9)); nullopt when the
/// seconds do not fit ROS's int32 (never wrapped).
std::optional<ros_time::Time_> to_ros_time(int64_t stamp_ns, int64_t offset_ns);
/// stamp_ns of a ROS Time: sec * 1e9 + nanosec - offset_ns; nullopt when nanosec >= 1e9 or
/// sec < 0 (not a time a sensor stamps).
std::optional<int64_t> from_ros_time(const ros_time::Time_& t, int64_t offset_ns);

/// sensor_msgs/Imu of an attitude estimate: orientation = q_world_body, orientation_covariance =
/// attitude_covariance (rad^2, rotation about the world axes, row-major: the layout of both).
/// Angular velocity and linear acceleration (specific force) from `sample`, the IMU sample the
/// estimate was computed from (covariance all zeros: unknown); absent (element 0 = -1, values 0)
/// when `sample` is null or flags the channel invalid. frame_id = frames.body: ROS's Imu gives
/// the orientation of that frame in the fixed (world) frame.
ros_sensor::Imu_ attitude_to_imu(const msg::AttitudeEstimate& estimate, const msg::ImuSample* sample,
                                 const Frames& frames, int64_t offset_ns);
/// The heading status companion of attitude_to_imu() (sensor_msgs/Imu has no field for it; topic
/// `<ns>/<filter>/heading_status`, docs/ROS2.md): diagnostic_msgs/DiagnosticArray with the same
/// header.stamp as the Imu and one DiagnosticStatus: level OK (0) when the heading is verified,
/// WARN (1) when unverified or without an absolute reference; name "poise/<filter>/heading";
/// message "verified" | "unverified" | "no_reference" (the IDL's HEADING_*, lower case);
/// hardware_id the estimate's sensor_id; values heading_status (the same word) and yaw_sigma_deg
/// (the square root of orientation_covariance[8], deg, the yaw variance a fuser reads).
ros_diag::DiagnosticArray_ heading_status_to_diagnostics(const msg::AttitudeEstimate& estimate,
                                                         const std::string& filter, const Frames& frames,
                                                         int64_t offset_ns);
/// "verified", "unverified", "no_reference" (an out-of-range value: "unknown").
std::string heading_status_word(msg::HeadingStatus status);
/// sensor_msgs/Imu of a raw sample (`imu/data_raw`): orientation absent (element 0 = -1).
ros_sensor::Imu_ sample_to_imu(const msg::ImuSample& sample, const Frames& frames, int64_t offset_ns);
/// sensor_msgs/MagneticField in tesla; nullopt when the sample carries no magnetometer.
std::optional<ros_sensor::MagneticField_> sample_to_mag(const msg::ImuSample& sample, const Frames& frames,
                                                        int64_t offset_ns);
/// sensor_msgs/FluidPressure in Pa (variance 0: unknown); nullopt without a pressure.
std::optional<ros_sensor::FluidPressure_> sample_to_pressure(const msg::ImuSample& sample,
                                                             const Frames& frames, int64_t offset_ns);

/// The 6x6 pose covariance [x y z rx ry rz] of poise's 9x9 [p v theta] (position and attitude
/// blocks and their cross terms).
std::array<double, 36> pose_covariance(const msg::PoseEstimate& estimate);
/// geometry_msgs/PoseWithCovarianceStamped of a pose estimate (frame_id = frames.world).
ros_geo::PoseWithCovarianceStamped_ pose_to_ros(const msg::PoseEstimate& estimate, const Frames& frames,
                                                int64_t offset_ns);
/// nav_msgs/Odometry of a pose estimate: pose as pose_to_ros; twist in the body frame (ROS: in
/// child_frame_id): linear = R^T v_world with covariance R^T C_v R; angular = the gyro of
/// `sample` (covariance block zeros: unknown), or absent (0 with -1 on its diagonal) without one.
ros_nav::Odometry_ pose_to_odometry(const msg::PoseEstimate& estimate, const msg::ImuSample* sample,
                                    const Frames& frames, int64_t offset_ns);
/// nav_msgs/Odometry of an altitude estimate: position.z = height_m and twist.linear.z =
/// vertical_velocity_mps (the body's vertical velocity is given in the world's up axis: child
/// frame = frames.world); both variances 0 (unknown: AltitudeEstimate carries none); x, y,
/// orientation and the other velocities are absent (-1 on their diagonal).
ros_nav::Odometry_ altitude_to_odometry(const msg::AltitudeEstimate& estimate, const Frames& frames,
                                        int64_t offset_ns);
/// tf2_msgs/TFMessage with the one transform world -> body (rotation q_world_body, translation
/// `position_m` in world).
ros_tf::TFMessage_ to_tf(int64_t stamp_ns, const msg::Quaternion& q_world_body,
                         const msg::Vector3& position_m, const Frames& frames, int64_t offset_ns);

/// True when every double of the message is finite (what the bridge checks before writing).
bool all_finite(const ros_sensor::Imu_& m);
bool all_finite(const ros_sensor::MagneticField_& m);
bool all_finite(const ros_sensor::FluidPressure_& m);
bool all_finite(const ros_geo::PoseWithCovarianceStamped_& m);
bool all_finite(const ros_nav::Odometry_& m);
bool all_finite(const ros_tf::TFMessage_& m);
bool all_finite(const ros_diag::DiagnosticArray_& m);

/// The DDS topic of a ROS 2 topic name: "rt/" + the name without its leading '/'. Throws
/// std::invalid_argument naming `ros_name` when it is not a ROS name (empty, characters other
/// than [A-Za-z0-9_/], a token starting with a digit, "//", or a trailing '/').
std::string dds_topic(const std::string& ros_name);

}  // namespace poise::ros2
