// The camera pipeline as a DDS component ("camera" in host files; `poise camera`):
// source -> CameraPipeline -> `tag_detections` (every frame) and `vision_pose` (frames with a valid
// world pose), plus `diagnostics` (component_name "camera") once per diagnostics period.
// Runs its own capture thread.
//
// Component parameters (host file or `poise camera` options):
//   source: /dev/video0            (required; see capture.h for SPEC forms)
//   intrinsics_file: cam.yaml      (required; OpenCV or ROS camera_info YAML)
//   tags_file: tags.yaml           (required; tag map)
//   config_file: camera.yaml       (optional; config/camera/camera.yaml format)
//   diagnostics_period_s: 1.0
//   pace: true                     (synthetic source: hold its fps in real time)
//   capture_delay_ms: 12.5         (optional; overrides the config's capture.delay_ms: the stamp is
//                                   the grab time minus this, the prior of the camera-IMU time
//                                   offset; the selective EKF estimates what is left, issue 36)
#pragma once

#include "poise/camera/capture.h"
#include "poise/camera/pipeline.h"
#include "poise/runtime/component.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace poise::camera {

struct CameraNodeOptions {
  std::string source;
  std::string intrinsics_file;
  std::string tags_file;
  std::string config_file;
  double diagnostics_period_s = 1.0;
  bool pace = true;
  double capture_delay_ms = -1.0;  ///< < 0: the config's capture.delay_ms
  bool log_to_stderr = true;
};

/// Parses component parameters (runtime::ConfigError naming the key and what to fix).
CameraNodeOptions camera_node_options(const runtime::ComponentSpec& spec);

class CameraNode : public runtime::Component {
 public:
  /// Loads and validates intrinsics, tag map and config, opens the source (runtime::ConfigError).
  CameraNode(const CameraNodeOptions& options, const std::string& instance_name,
             runtime::HostContext& host);
  ~CameraNode() override;
  CameraNode(const CameraNode&) = delete;
  CameraNode& operator=(const CameraNode&) = delete;

  void start() override;
  void stop() override;
  [[nodiscard]] std::string status() const override;
  /// Frames processed (the service watchdog's health check).
  [[nodiscard]] std::optional<uint64_t> produced() const override { return frames_.load(); }

  /// True once the source has ended (file/list/synthetic done) or failed; error() says why.
  [[nodiscard]] bool finished() const { return finished_.load(); }
  [[nodiscard]] std::string error() const;
  /// True when processing stopped on a setup error (e.g. frame size differs from the calibration).
  [[nodiscard]] bool failed() const { return failed_.load(); }
  [[nodiscard]] uint64_t frames() const { return frames_.load(); }
  [[nodiscard]] uint64_t poses_published() const { return poses_.load(); }
  [[nodiscard]] const std::string& sensor_id() const { return sensor_id_; }

 private:
  void run();
  void publish_diagnostics(int64_t stamp_ns);
  void log(const std::string& message) const;

  CameraNodeOptions options_;
  CameraConfig config_;
  std::string sensor_id_;
  std::unique_ptr<CameraPipeline> pipeline_;
  std::unique_ptr<FrameSource> source_;
  dds::Writer<msg::TagDetectionsPubSubType> detections_writer_;
  dds::Writer<msg::VisionPosePubSubType> pose_writer_;
  dds::Writer<msg::FilterDiagnosticsPubSubType> diag_writer_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> finished_{false};
  std::atomic<bool> failed_{false};
  std::atomic<uint64_t> frames_{0};
  std::atomic<uint64_t> poses_{0};
  std::thread thread_;
  // Owned by the capture thread.
  uint32_t detections_seq_ = 0;
  uint32_t pose_seq_ = 0;
  uint32_t diag_seq_ = 0;
  uint64_t source_skipped_ = 0;
  uint64_t write_failures_ = 0;
  uint64_t truncated_ = 0;
  uint64_t period_frames_ = 0;
  double period_detect_ms_ = 0.0;
  double period_total_ms_ = 0.0;
  double period_latency_ms_ = 0.0;
  int64_t period_start_ns_ = 0;
  mutable std::mutex status_mutex_;
  std::string status_;
  std::string error_;
};

}  // namespace poise::camera

namespace poise::runtime {
/// Registers the "camera" component type (poise_add_component_module).
void register_camera_component(ComponentRegistry& registry);
}  // namespace poise::runtime
