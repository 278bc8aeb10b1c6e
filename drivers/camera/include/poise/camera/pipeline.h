// The camera pipeline: frame -> tag detections (+ per-tag pose) -> camera (and body) pose in world.
// No DDS and no clocks here (stamps come with the frame; durations measured for diagnostics only).
#pragma once

#include "poise/camera/image_file.h"
#include "poise/camera/capture.h"
#include "poise/camera/detector.h"
#include "poise/camera/intrinsics.h"
#include "poise/camera/tag_map.h"
#include "poise/camera/tag_pose.h"
#include "poise/camera/world_pose.h"
#include "poise/core/types.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace poise::camera {

/// Everything in config/camera/camera.yaml. Defaults live here (and only here).
struct CameraConfig {
  std::string sensor_id = "camera0";  ///< DDS key of this camera's samples
  std::string frame_id = "camera";    ///< frame name on tag_detections
  double capture_delay_s = 0.0;  ///< exposure + transfer delay subtracted from host stamps, s
  int width_px = 0;              ///< requested device resolution (0 = driver default)
  int height_px = 0;
  double fps = 0.0;              ///< requested device rate (0 = driver default)
  /// Largest image file accepted by the `images` source (width x height, from the file header).
  int64_t max_image_pixels = ImageLimits{}.max_pixels;
  DetectorParams detector;
  TagPoseParams tag_pose;
  WorldPoseParams world_pose;
  /// Edge length assumed for detected ids that are not in the map (0 = no pose for them), m.
  double unknown_tag_size_m = 0.0;
  /// Camera pose in the body (IMU) frame; when set, the body pose is published too.
  std::optional<Eigen::Isometry3d> T_body_camera;
};

/// Throws ConfigError on unknown keys, wrong types and out-of-range values.
CameraConfig parse_camera_config(const std::string& yaml_text, const std::string& source);
CameraConfig load_camera_config(const std::string& path);

struct DetectionResult {
  TagDetection detection;                      ///< as detected (distorted pixels)
  std::array<Eigen::Vector2d, 4> ideal_px = zero_corners();  ///< undistorted (pinhole) corners, px
  bool in_map = false;
  double size_m = 0.0;                          ///< size used for the pose (0 = none)
  bool pose_computed = false;
  TagPoseEstimate pose;                         ///< valid iff pose_computed
};

struct FrameResult {
  int64_t stamp_ns = 0;
  int width_px = 0;
  int height_px = 0;
  std::vector<DetectionResult> detections;
  WorldPoseResult world;           ///< world.valid: camera pose usable
  bool body_valid = false;         ///< world.valid and an extrinsic is configured
  Eigen::Isometry3d T_world_body = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> covariance_body = Eigen::Matrix<double, 6, 6>::Identity();
  double detect_ms = 0.0;          ///< libapriltag time (incl. grey conversion if any), ms
  double total_ms = 0.0;           ///< whole process() call, ms
};

class CameraPipeline {
 public:
  /// Validates everything (throws ConfigError): family of the map vs detector, etc.
  CameraPipeline(const CameraConfig& config, const CameraIntrinsics& intrinsics,
                 const TagMap& tag_map);

  /// Processes one frame. Throws ConfigError when the frame size differs from the calibration.
  FrameResult process(const Frame& frame);

  /// The measurement for the estimators: body pose if an extrinsic is set, else camera pose.
  [[nodiscard]] static PoseMeasurement to_measurement(const FrameResult& result);

  /// Counters by reason: frames, frames_with_tags, world_pose_ok, rejected_ambiguous, ...
  [[nodiscard]] const std::map<std::string, uint64_t>& counters() const { return counters_; }
  [[nodiscard]] const CameraConfig& config() const { return config_; }
  [[nodiscard]] const CameraIntrinsics& intrinsics() const { return intrinsics_; }
  [[nodiscard]] TagDetector& detector() { return detector_; }
  /// Replaces the tag map (e.g. a re-surveyed map) without recreating the detector.
  void set_tag_map(const TagMap& tag_map);
  /// Replaces the world-pose parameters (validated; throws ConfigError).
  void set_world_pose_params(const WorldPoseParams& params);

 private:
  CameraConfig config_;
  CameraIntrinsics intrinsics_;
  TagMap map_;
  TagDetector detector_;
  cv::Matx33d k_;
  cv::Mat distortion_;
  std::map<std::string, uint64_t> counters_;
  cv::Mat gray_;
};

}  // namespace poise::camera
