// Pose of one tag in the camera frame from its four undistorted corners (IPPE-square).
//
// Frames: camera x right, y down, z forward (OpenCV); tag x right, y up, z out of the printed face
// (see renderer.h). T_camera_tag maps tag-frame points into the camera frame.
// A planar square seen from afar has two poses that explain the corners almost equally well (the
// "flip"); IPPE returns both. ambiguity_ratio = RMS(best) / RMS(second) in [0, 1]: near 0 the
// choice is clear, near 1 both fit. The estimate is `ambiguous` when the ratio exceeds
// ambiguity_ratio_max AND the two rotations differ by more than ambiguity_min_angle_rad (when they
// differ by less, either choice is within that angle and the pose is kept).
#pragma once

#include "poise/camera/intrinsics.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>

namespace poise::camera {

struct TagPoseParams {
  /// Above this best/second RMS ratio the two IPPE solutions are considered indistinguishable.
  double ambiguity_ratio_max = 0.3;
  /// ... but only when they differ by more than this angle, rad (default 8 deg).
  double ambiguity_min_angle_rad = 0.13962634015954636;
  /// A tag whose best solution reprojects worse than this RMS, px, is rejected (bad corners).
  double max_reprojection_rms_px = 3.0;
};

/// Throws ConfigError for out-of-range values.
void validate_tag_pose_params(const TagPoseParams& params);

struct TagPoseSolution {
  Eigen::Isometry3d T_camera_tag = Eigen::Isometry3d::Identity();
  double reprojection_rms_px = 0.0;  ///< over the 4 corners, px
};

struct TagPoseEstimate {
  bool valid = false;          ///< best solution accepted (not ambiguous, reprojection ok)
  bool ambiguous = false;      ///< see header comment
  bool reprojection_too_large = false;
  TagPoseSolution best;        ///< lower reprojection error
  TagPoseSolution second;      ///< the other IPPE solution (the flip)
  double ambiguity_ratio = 0.0;      ///< best.rms / second.rms, [0, 1]
  double solutions_angle_rad = 0.0;  ///< rotation between best and second, rad
};

/// corners_px: ideal (undistorted, pinhole) pixel corners in libapriltag's order; size_m: the
/// detected square's edge; camera_matrix: K of the ideal pinhole camera.
TagPoseEstimate estimate_tag_pose(const std::array<Eigen::Vector2d, 4>& corners_px, double size_m,
                                  const cv::Matx33d& camera_matrix, const TagPoseParams& params);

/// Angle of the rotation between two rotation matrices, rad, in [0, pi].
double rotation_angle_between(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b);

}  // namespace poise::camera
