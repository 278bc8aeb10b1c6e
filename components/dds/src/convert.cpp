#include "poise/dds/convert.h"

#include <cmath>

namespace poise::dds {

msg::Vector3 to_msg(const Eigen::Vector3d& v) {
  msg::Vector3 out;
  out.x(v.x());
  out.y(v.y());
  out.z(v.z());
  return out;
}

Eigen::Vector3d from_msg(const msg::Vector3& v) { return {v.x(), v.y(), v.z()}; }

msg::Quaternion to_msg(const Eigen::Quaterniond& q) {
  msg::Quaternion out;
  out.w(q.w());
  out.x(q.x());
  out.y(q.y());
  out.z(q.z());
  return out;
}

Eigen::Quaterniond from_msg(const msg::Quaternion& q) { return {q.w(), q.x(), q.y(), q.z()}; }

msg::Header make_header(int64_t stamp_ns, uint32_t seq, const std::string& frame_id) {
  msg::Header header;
  header.stamp_ns(stamp_ns);
  header.seq(seq);
  header.frame_id(frame_id);
  return header;
}

msg::ImuSample to_msg(const ImuSample& sample, const std::string& sensor_id) {
  msg::ImuSample out;
  out.header(make_header(sample.stamp_ns, sample.seq, "body"));
  out.sensor_id(sensor_id);
  out.accel_mps2(to_msg(sample.accel_mps2));
  out.gyro_rps(to_msg(sample.gyro_rps));
  out.mag_ut(to_msg(sample.mag_ut));
  out.pressure_pa(sample.pressure_pa);
  out.temperature_c(sample.temperature_c);
  msg::ImuValidity valid;
  valid.accel(sample.has_accel);
  valid.gyro(sample.has_gyro);
  valid.mag(sample.has_mag);
  valid.pressure(sample.has_pressure);
  valid.temperature(sample.has_temperature);
  out.valid(valid);
  return out;
}

ImuSample from_msg(const msg::ImuSample& sample) {
  ImuSample out;
  out.stamp_ns = sample.header().stamp_ns();
  out.seq = sample.header().seq();
  out.accel_mps2 = from_msg(sample.accel_mps2());
  out.gyro_rps = from_msg(sample.gyro_rps());
  out.mag_ut = from_msg(sample.mag_ut());
  out.pressure_pa = sample.pressure_pa();
  out.temperature_c = sample.temperature_c();
  out.has_accel = sample.valid().accel();
  out.has_gyro = sample.valid().gyro();
  out.has_mag = sample.valid().mag();
  out.has_pressure = sample.valid().pressure();
  out.has_temperature = sample.valid().temperature();
  return out;
}

std::optional<PoseMeasurement> body_pose_from_msg(const msg::VisionPose& pose) {
  if (!pose.body_valid()) {
    return std::nullopt;
  }
  PoseMeasurement out;
  out.stamp_ns = pose.capture_stamp_ns();
  out.p_world_body_m = from_msg(pose.pose_world_body().position_m());
  out.q_world_body = from_msg(pose.pose_world_body().orientation());
  out.covariance = from_array<6, 6>(pose.covariance());
  return out;
}

CameraPoseMeasurement camera_pose_from_msg(const msg::VisionPose& pose) {
  CameraPoseMeasurement out;
  out.stamp_ns = pose.capture_stamp_ns();
  out.p_world_camera_m = from_msg(pose.pose_world_camera().position_m());
  out.q_world_camera = from_msg(pose.pose_world_camera().orientation());
  out.covariance = from_array<6, 6>(pose.covariance());
  return out;
}

bool is_finite(const msg::Vector3& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

bool is_finite(const msg::Quaternion& q) {
  return std::isfinite(q.w()) && std::isfinite(q.x()) && std::isfinite(q.y()) &&
         std::isfinite(q.z());
}

}  // namespace poise::dds
