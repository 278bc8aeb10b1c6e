// Synthetic camera images of AprilTags for tests, benchmarks and the `synthetic` capture source.
//
// Tags are drawn from the family's own codes and bit layout (TagFamilyLayout::pattern) by ray
// casting: every output pixel is supersampled, each sample's ray is found by inverting the lens
// model (the same OpenCV distortion the pipeline undistorts with), intersected with each tag plane
// and the nearest hit's cell colour taken. Then optional Gaussian blur and Gaussian noise from a
// seeded generator: the same inputs and seed give the same image, bit for bit.
//
// Tag frame (also the tag map's): origin at the tag centre, x to the tag's right, y up, z out of the
// printed face towards a viewer; the tag is upright when its pattern row 0 is at +y. size_m is the
// edge of the detected square (width_at_border cells; for tag36h11 the black square, 8 of its 10
// cells). Around the pattern a white paper margin is drawn.
#pragma once

#include "poise/camera/detector.h"
#include "poise/camera/intrinsics.h"

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstdint>
#include <vector>

namespace poise::camera {

/// A tag placed in the world.
struct SceneTag {
  int id = 0;
  double size_m = 0.16;  ///< detected-square edge, m
  Eigen::Isometry3d T_world_tag = Eigen::Isometry3d::Identity();
};

struct RenderOptions {
  double blur_sigma_px = 0.0;   ///< Gaussian blur after sampling, px (0 = none)
  double noise_sigma = 0.0;     ///< additive Gaussian noise, grey levels (0 = none)
  uint64_t seed = 1;            ///< noise seed
  double white = 235.0;         ///< white cells and paper, grey level
  double black = 20.0;          ///< black cells, grey level
  double background = 120.0;    ///< mean background grey level (a gentle gradient is added)
  double paper_margin_cells = 1.0;  ///< white paper around the pattern, cells
};

/// Renders scenes for one camera and one family. Precomputes the rays of every sample once.
class SceneRenderer {
 public:
  /// supersample: samples per pixel along each axis (>= 1). Throws ConfigError on bad input.
  SceneRenderer(const CameraIntrinsics& intrinsics, const std::string& family, int supersample = 3);

  /// An 8-bit grey image of the tags seen from the camera pose T_world_camera (camera frame: x
  /// right, y down, z forward).
  [[nodiscard]] cv::Mat render(const std::vector<SceneTag>& tags,
                               const Eigen::Isometry3d& T_world_camera,
                               const RenderOptions& options) const;

  /// The true (distorted) pixel positions of a tag's corners, in libapriltag's order.
  [[nodiscard]] std::array<Eigen::Vector2d, 4> project_corners(
      const SceneTag& tag, const Eigen::Isometry3d& T_world_camera) const;

  [[nodiscard]] const CameraIntrinsics& intrinsics() const { return intrinsics_; }
  [[nodiscard]] const TagFamilyLayout& layout() const { return layout_; }

 private:
  CameraIntrinsics intrinsics_;
  TagFamilyLayout layout_;
  int supersample_;
  std::vector<cv::Point2f> rays_;  ///< normalised (x/z, y/z) per sample, row-major
};

/// A camera pose at `eye` looking at `target` (camera z forward), image "up" towards `up` (camera
/// y down = -up projected). `up` must not be parallel to the viewing direction.
Eigen::Isometry3d look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                          const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

/// A tag's corner positions in its own frame, in libapriltag's detection order:
/// (-s/2,-s/2), (s/2,-s/2), (s/2,s/2), (-s/2,s/2) with s = size_m (bottom-left first, CCW in the
/// image).
std::array<Eigen::Vector3d, 4> tag_corners_in_tag(double size_m);

}  // namespace poise::camera
