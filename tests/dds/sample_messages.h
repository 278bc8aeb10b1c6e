// Deterministic, fully populated sample messages of every topic type, for round-trip tests.
// Every field gets a distinct non-default value derived from `salt`, so a dropped or swapped field
// makes the equality check fail.
#pragma once

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <cstdint>
#include <string>

namespace poise::testing {

inline double value(int salt, int field) { return salt * 1000.0 + field + 0.25; }

inline msg::Header header(int salt, const char* frame) {
  msg::Header h;
  h.stamp_ns(1700000000000000000LL + salt);
  h.seq(static_cast<uint32_t>(salt * 7 + 1));
  h.frame_id(frame);
  return h;
}

inline msg::Vector3 vec(int salt, int base) {
  msg::Vector3 v;
  v.x(value(salt, base));
  v.y(value(salt, base + 1));
  v.z(value(salt, base + 2));
  return v;
}

inline msg::Quaternion quat(int salt, int base) {
  msg::Quaternion q;
  q.w(value(salt, base));
  q.x(value(salt, base + 1));
  q.y(value(salt, base + 2));
  q.z(value(salt, base + 3));
  return q;
}

inline msg::Pose pose(int salt, int base) {
  msg::Pose p;
  p.position_m(vec(salt, base));
  p.orientation(quat(salt, base + 3));
  return p;
}

template <std::size_t N>
void fill(std::array<double, N>& a, int salt, int base) {
  for (std::size_t i = 0; i < N; ++i) {
    a[i] = value(salt, base + static_cast<int>(i));
  }
}

inline msg::ImuSample make_imu(int salt) {
  msg::ImuSample m;
  m.header(header(salt, "body"));
  m.sensor_id("imu" + std::to_string(salt));
  m.accel_mps2(vec(salt, 1));
  m.gyro_rps(vec(salt, 4));
  m.mag_ut(vec(salt, 7));
  m.pressure_pa(value(salt, 10));
  m.temperature_c(value(salt, 11));
  msg::ImuValidity v;
  v.accel(true);
  v.gyro(false);
  v.mag(true);
  v.pressure(false);
  v.temperature(true);
  m.valid(v);
  return m;
}

inline msg::VehicleInput make_vehicle_input(int salt) {
  msg::VehicleInput m;
  m.header(header(salt, "body"));
  m.sensor_id("car" + std::to_string(salt));
  m.speed_mps(value(salt, 1));
  m.speed_valid(true);
  return m;
}

inline msg::TagDetections make_tag_detections(int salt) {
  msg::TagDetections m;
  m.header(header(salt, "camera"));
  m.sensor_id("cam" + std::to_string(salt));
  m.image_width_px(640);
  m.image_height_px(480);
  for (int i = 0; i < 3; ++i) {
    msg::TagDetection d;
    d.id(salt + i);
    d.family("tag36h11");
    d.hamming(i);
    d.decision_margin(value(salt, 20 + i));
    for (std::size_t c = 0; c < 4; ++c) {
      d.corners()[c].x_px(value(salt, 30 + i * 8 + static_cast<int>(c) * 2));
      d.corners()[c].y_px(value(salt, 31 + i * 8 + static_cast<int>(c) * 2));
    }
    d.pose_valid(i != 1);
    d.pose_camera_tag(pose(salt, 70 + i * 7));
    d.tag_size_m(0.16);
    d.reprojection_error_px(value(salt, 95 + i));
    d.ambiguity_ratio(value(salt, 98 + i));
    d.in_map(i == 0);
    m.detections().push_back(d);
  }
  return m;
}

inline msg::VisionPose make_vision_pose(int salt) {
  msg::VisionPose m;
  m.header(header(salt, "world"));
  m.sensor_id("cam" + std::to_string(salt));
  m.capture_stamp_ns(m.header().stamp_ns());
  m.pose_world_camera(pose(salt, 1));
  m.body_valid(true);
  m.pose_world_body(pose(salt, 8));
  fill(m.covariance(), salt, 20);
  m.reprojection_rms_px(value(salt, 60));
  m.tag_ids({salt, salt + 1, salt + 5});
  return m;
}

inline msg::AttitudeEstimate make_attitude(int salt) {
  msg::AttitudeEstimate m;
  m.header(header(salt, "world"));
  m.sensor_id("pkf" + std::to_string(salt));
  m.filter_id("parallel_kf");
  m.q_world_body(quat(salt, 1));
  m.roll_rad(value(salt, 5));
  m.pitch_rad(value(salt, 6));
  m.yaw_rad(value(salt, 7));
  fill(m.attitude_covariance(), salt, 8);
  m.ext_accel_body_mps2(vec(salt, 20));
  m.ext_accel_world_mps2(vec(salt, 23));
  m.mag_disturbance_body_ut(vec(salt, 26));
  m.mag_disturbance_world_ut(vec(salt, 29));
  m.mag_disturbance_norm_ut(value(salt, 32));
  m.mag_disturbance_angle_rad(value(salt, 33));
  m.mag_trusted(true);
  m.sources_fused(msg::SOURCE_GYRO | msg::SOURCE_ACCEL | msg::SOURCE_MAG);
  m.gyro_bias_rps(vec(salt, 34));
  return m;
}

inline msg::PoseEstimate make_pose_estimate(int salt) {
  msg::PoseEstimate m;
  m.header(header(salt, "world"));
  m.sensor_id("sekf" + std::to_string(salt));
  m.filter_id("selective_ekf");
  m.position_m(vec(salt, 1));
  m.velocity_mps(vec(salt, 4));
  m.q_world_body(quat(salt, 7));
  fill(m.covariance(), salt, 11);
  m.sources_fused(msg::SOURCE_GYRO | msg::SOURCE_VISION);
  return m;
}

inline msg::AltitudeEstimate make_altitude(int salt) {
  msg::AltitudeEstimate m;
  m.header(header(salt, "world"));
  m.sensor_id("alt" + std::to_string(salt));
  m.filter_id("altitude");
  m.method("pi_cf_zupt");
  m.height_m(value(salt, 1));
  m.vertical_velocity_mps(value(salt, 2));
  m.vertical_accel_mps2(value(salt, 3));
  m.stationary(true);
  m.baro_valid(true);
  m.baro_height_m(value(salt, 4));
  m.reference_pressure_pa(value(salt, 5));
  return m;
}

inline msg::FilterDiagnostics make_diagnostics(int salt) {
  msg::FilterDiagnostics m;
  m.header(header(salt, "body"));
  m.sensor_id("pkf" + std::to_string(salt));
  m.component_name("parallel_kf");
  for (int i = 0; i < 2; ++i) {
    msg::SourceStatus s;
    s.source(i == 0 ? "accel" : "mag");
    s.fresh(true);
    s.fused(i == 0);
    s.reason(i == 0 ? "" : "disturbance_angle");
    s.innovation({value(salt, 10 + i), value(salt, 11 + i), value(salt, 12 + i)});
    s.innovation_variance({value(salt, 20 + i), value(salt, 21 + i), value(salt, 22 + i)});
    s.test_ratio(value(salt, 30 + i));
    s.last_fused_stamp_ns(123456789 + salt + i);
    s.fused_count(static_cast<uint64_t>(1000 + i));
    s.rejected_count(static_cast<uint64_t>(7 + i));
    m.sources().push_back(s);
  }
  msg::Counter c;
  c.name("rejected_nan");
  c.value(static_cast<uint64_t>(salt + 3));
  m.counters().push_back(c);
  msg::Metric metric;
  metric.name("rate");
  metric.value(value(salt, 40));
  metric.unit("Hz");
  m.metrics().push_back(metric);
  return m;
}

}  // namespace poise::testing
