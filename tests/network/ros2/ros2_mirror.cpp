#include "ros2_mirror.h"

namespace poise::nettest::ros2 {

::builtin_interfaces::msg::dds_::Time_ to_ros_time(int64_t stamp_ns, int64_t offset_ns) {
  constexpr int64_t kNsPerS = 1000000000LL;
  const int64_t t = stamp_ns + offset_ns;
  int64_t sec = t / kNsPerS;
  int64_t nsec = t % kNsPerS;
  if (nsec < 0) {
    nsec += kNsPerS;
    sec -= 1;
  }
  ::builtin_interfaces::msg::dds_::Time_ out;
  out.sec(static_cast<int32_t>(sec));
  out.nanosec(static_cast<uint32_t>(nsec));
  return out;
}

ros_msg::Imu_ to_ros_imu(const msg::ImuSample& in, int64_t offset_ns) {
  ros_msg::Imu_ out;
  out.header().stamp(to_ros_time(in.header().stamp_ns(), offset_ns));
  out.header().frame_id(in.header().frame_id().to_string());
  out.orientation().x(0.0);
  out.orientation().y(0.0);
  out.orientation().z(0.0);
  out.orientation().w(1.0);
  out.orientation_covariance().fill(0.0);
  out.orientation_covariance()[0] = -1.0;
  out.angular_velocity().x(in.gyro_rps().x());
  out.angular_velocity().y(in.gyro_rps().y());
  out.angular_velocity().z(in.gyro_rps().z());
  out.angular_velocity_covariance().fill(0.0);
  if (!in.valid().gyro()) {
    out.angular_velocity_covariance()[0] = -1.0;
  }
  out.linear_acceleration().x(in.accel_mps2().x());
  out.linear_acceleration().y(in.accel_mps2().y());
  out.linear_acceleration().z(in.accel_mps2().z());
  out.linear_acceleration_covariance().fill(0.0);
  if (!in.valid().accel()) {
    out.linear_acceleration_covariance()[0] = -1.0;
  }
  return out;
}

ros_geo::PoseWithCovarianceStamped_ to_ros_pose(const msg::PoseEstimate& in, int64_t offset_ns) {
  ros_geo::PoseWithCovarianceStamped_ out;
  out.header().stamp(to_ros_time(in.header().stamp_ns(), offset_ns));
  out.header().frame_id(in.header().frame_id().to_string());
  out.pose().pose().position().x(in.position_m().x());
  out.pose().pose().position().y(in.position_m().y());
  out.pose().pose().position().z(in.position_m().z());
  out.pose().pose().orientation().x(in.q_world_body().x());
  out.pose().pose().orientation().y(in.q_world_body().y());
  out.pose().pose().orientation().z(in.q_world_body().z());
  out.pose().pose().orientation().w(in.q_world_body().w());
  // poise 9x9 order [p(0..2) v(3..5) theta(6..8)] -> ROS 6x6 [p(0..2) rot(3..5)].
  const auto source = [](size_t i) { return i < 3 ? i : i + 3; };
  for (size_t r = 0; r < 6; ++r) {
    for (size_t c = 0; c < 6; ++c) {
      out.pose().covariance()[r * 6 + c] = in.covariance()[source(r) * 9 + source(c)];
    }
  }
  return out;
}

}  // namespace poise::nettest::ros2
