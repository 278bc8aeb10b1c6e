// Pure conversions between poise core types (Eigen, SI) and IDL messages. No DDS entities here:
// every function is a plain value transformation with its own tests (STYLE.md habit 2).
#pragma once

#include "poise/core/types.h"

#include <poise/msg/common.h>
#include <poise/msg/diagnostics.h>
#include <poise/msg/estimates.h>
#include <poise/msg/imu.h>
#include <poise/msg/vision.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <optional>
#include <string>

namespace poise::dds {

msg::Vector3 to_msg(const Eigen::Vector3d& v);
Eigen::Vector3d from_msg(const msg::Vector3& v);

/// Hamilton quaternion, (w, x, y, z) order on the wire.
msg::Quaternion to_msg(const Eigen::Quaterniond& q);
Eigen::Quaterniond from_msg(const msg::Quaternion& q);

/// Fills a header (stamp, seq, frame).
msg::Header make_header(int64_t stamp_ns, uint32_t seq, const std::string& frame_id);

/// ImuSample <-> msg::ImuSample (validity flags mapped one to one; frame_id "body").
msg::ImuSample to_msg(const ImuSample& sample, const std::string& sensor_id);
ImuSample from_msg(const msg::ImuSample& sample);

/// A vision pose message -> the body pose measurement. nullopt when the message carries no body
/// pose (body_valid false: no camera-to-body extrinsic configured at the camera): the caller counts
/// it as a rejection, it never substitutes the camera pose for the body's.
std::optional<PoseMeasurement> body_pose_from_msg(const msg::VisionPose& pose);

/// A vision pose message -> the camera pose (for estimators that apply their own extrinsic). The
/// covariance is the message's: of the body pose when body_valid (its rotation block is the
/// camera's too; its position block ignores the lever arm's share).
CameraPoseMeasurement camera_pose_from_msg(const msg::VisionPose& pose);

/// Row-major copy of a fixed-size Eigen matrix into an IDL array, and back.
template <int R, int C, std::size_t N>
void to_array(const Eigen::Matrix<double, R, C>& m, std::array<double, N>& out) {
  static_assert(static_cast<std::size_t>(R * C) == N, "size mismatch");
  for (int r = 0; r < R; ++r) {
    for (int c = 0; c < C; ++c) {
      out[static_cast<std::size_t>(r * C + c)] = m(r, c);
    }
  }
}
template <int R, int C, std::size_t N>
Eigen::Matrix<double, R, C> from_array(const std::array<double, N>& in) {
  static_assert(static_cast<std::size_t>(R * C) == N, "size mismatch");
  Eigen::Matrix<double, R, C> m;
  for (int r = 0; r < R; ++r) {
    for (int c = 0; c < C; ++c) {
      m(r, c) = in[static_cast<std::size_t>(r * C + c)];
    }
  }
  return m;
}

/// True if every double in the vector/quaternion is finite.
bool is_finite(const msg::Vector3& v);
bool is_finite(const msg::Quaternion& q);

}  // namespace poise::dds
