// Frame sources behind one interface: V4L2 device, video file, image directory/glob/list, synthetic.
//
// SPEC strings (open_source):
//   /dev/videoN | v4l2:N | v4l2:/dev/videoN   a V4L2 camera through OpenCV
//   file:PATH | PATH.{mp4,avi,mkv,mov,webm}   a video file
//   DIR | 'GLOB*' | IMAGE                     images (sorted by name)
//   synthetic[:frames=N,fps=F,seed=S,noise=G,blur=B]   rendered tags from the tag map (needs a
//                                               SyntheticScene in SourceOptions)
// Capture stamps (stamp_ns, CLOCK_MONOTONIC domain): V4L2 buffers carry the driver's capture
// timestamp (used when it is plausible: within max_driver_skew of the host clock); otherwise, and
// for every other source, host time at grab minus SourceOptions::delay_ns (exposure + transfer).
// The clock is injected (SourceOptions::clock) so tests control time.
#pragma once

#include "poise/camera/image_file.h"
#include "poise/camera/intrinsics.h"
#include "poise/camera/renderer.h"

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace poise::camera {

/// Returns "now" in ns (CLOCK_MONOTONIC unless injected).
using Clock = std::function<int64_t()>;
int64_t monotonic_now_ns();

struct Frame {
  cv::Mat image;                 ///< 8-bit grey or BGR
  int64_t stamp_ns = 0;          ///< capture instant, ns
  bool stamp_from_driver = false;
  uint64_t index = 0;            ///< 0, 1, 2, ... per source
  std::string name;              ///< file path for image sources, else empty
  /// Ground truth camera pose (synthetic source only).
  std::optional<Eigen::Isometry3d> truth_T_world_camera;
};

enum class GrabStatus {
  kFrame,    ///< `frame` filled
  kSkipped,  ///< this item could not be read (message in `error`); try the next
  kEnd,      ///< no more frames (end of file / list)
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  /// Blocks for the next frame. `error` explains kSkipped.
  virtual GrabStatus grab(Frame& frame, std::string& error) = 0;
  /// Human-readable description, e.g. "v4l2 /dev/video0 640x480".
  [[nodiscard]] virtual std::string describe() const = 0;
};

/// What the synthetic source renders.
struct SyntheticScene {
  CameraIntrinsics intrinsics;
  std::string family = "tag36h11";
  std::vector<SceneTag> tags;
  /// Camera pose for frame i (default: a slow orbit in front of the tags, set by open_source).
  std::function<Eigen::Isometry3d(uint64_t)> trajectory;
};

struct SourceOptions {
  Clock clock = monotonic_now_ns;
  int64_t delay_ns = 0;                 ///< subtracted from host grab time
  int64_t max_driver_skew_ns = 1'000'000'000;  ///< driver stamps further from host time are ignored
  int width_px = 0;                     ///< requested device resolution (0 = driver default)
  int height_px = 0;
  double fps = 0.0;                     ///< requested device rate (0 = driver default)
  bool pace = false;                    ///< synthetic: sleep to hold fps (live demo)
  ImageLimits image_limits;             ///< image files: checked from the header before decoding
  std::optional<SyntheticScene> scene;  ///< required for "synthetic"
};

/// Opens a source. Throws ConfigError with what to do (missing device, no images, bad spec).
std::unique_ptr<FrameSource> open_source(const std::string& spec, const SourceOptions& options);

/// Expands an image spec (file, directory or glob) into a sorted file list (may be empty).
std::vector<std::string> expand_image_spec(const std::string& spec);

}  // namespace poise::camera
