// What Foxglove's panels read without setup, made from poise estimates: JSON messages with their
// JSON schemas (schema encoding "jsonschema", message encoding "json"). Pure C++17: input is a
// payload decoded by the one CDR decoder (poise/schema/cdr.h), output is JSON text.
//  - foxglove.FrameTransform (the 3D panel): world -> body of each attitude or pose estimate,
//    world -> camera of each vision pose. An attitude has no position: its frame is placed at a
//    fixed display offset (`FrameLayout`) so the filters' frames stand side by side with the
//    truth; poses and the camera keep their estimated position.
//  - poise.AttitudePlot (the Plot panel): roll/pitch/yaw, the magnetic disturbance (world vector,
//    norm, dip-angle deviation), whether the magnetometer was trusted, and the heading status
//    (heading_status word, heading_verified 1/0, yaw_sigma_deg from the covariance), per filter.
// Stamps: header.stamp_ns + offset_ns (the bridge's `stamps`: CLOCK_REALTIME - CLOCK_MONOTONIC
// so Foxglove's timeline, built from the receive times, and the messages agree; or 0).
#pragma once

#include "poise/schema/cdr.h"

#include <cstdint>
#include <map>
#include <optional>
#include <string>

namespace poise::foxglove {

inline constexpr const char* kFrameTransformSchemaName = "foxglove.FrameTransform";
inline constexpr const char* kAttitudePlotSchemaName = "poise.AttitudePlot";

/// JSON schema texts (draft 2020-12 style, as Foxglove's own schemas).
const std::string& frame_transform_schema();
const std::string& attitude_plot_schema();

/// Display offsets of position-less (attitude) frames: slot k is at (k * spacing_m, 0, 0).
/// Fixed slots for poise's filters (truth 0, parallel_kf 1, selective_ekf 2, gauss_newton 3,
/// vehicle 4), later slots for other names in the order they are first seen.
class FrameLayout {
 public:
  explicit FrameLayout(double spacing_m) : spacing_m_(spacing_m) {}
  /// x offset of `frame`, m.
  double offset_m(const std::string& frame);

 private:
  double spacing_m_;
  std::map<std::string, int> extra_;
};

/// The child frame of an estimate topic: "attitude/<f>" -> "<f>", "truth/attitude" -> "truth",
/// "pose/<f>" -> "<f>_pose", "truth/pose" -> "truth_pose", "vision_pose" -> "camera"; any other
/// topic: its name with '/' as '_'.
std::string child_frame(const std::string& topic);

/// A foxglove.FrameTransform JSON message, or nullopt when the payload lacks the fields or holds a
/// non-finite or zero quaternion / position (never a NaN on the wire).
///  - poise::msg::AttitudeEstimate: rotation q_world_body, translation (offset_x_m, 0, 0);
///  - poise::msg::PoseEstimate: rotation q_world_body, translation position_m;
///  - poise::msg::VisionPose: pose_world_camera.
std::optional<std::string> frame_transform_json(const std::string& type, const schema::Value& message,
                                                const std::string& parent_frame, const std::string& child,
                                                double offset_x_m, std::int64_t offset_ns);

/// A poise.AttitudePlot JSON message from an AttitudeEstimate (non-finite numbers become null).
std::optional<std::string> attitude_plot_json(const schema::Value& attitude, std::int64_t offset_ns);

}  // namespace poise::foxglove
