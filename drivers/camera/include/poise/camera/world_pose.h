// Camera pose in the world from all corners of all visible mapped tags, jointly.
//
// Notation: X_i world corner points (from the tag map), u_i their undistorted (ideal pinhole) pixel
// observations, T_world_camera = (R, p) the unknown. Residual r_i = pi(R^T (X_i - p)) - u_i, px.
// Perturbation (world frame, matching PoseMeasurement's covariance): p <- p + dp,
// R <- Exp(dtheta) R, parameters [dp, dtheta].
//   d X_c / d dp = -R^T,  d X_c / d dtheta = R^T [X_i - p]x,  pi = K * (x/z, y/z)
// Start: every IPPE solution (both, per mapped tag) mapped to the world; the best by joint RMS
// is refined with Levenberg-Marquardt. The best competing start whose rotation differs by more
// than ambiguity_min_angle_rad is refined too: world ambiguity ratio = RMS(best)/RMS(competitor).
// With a single tag the two IPPE solutions are the two minima: the tag's own ratio is used.
// Covariance = sigma^2 (J^T J)^-1 J^T S J (J^T J)^-1: S the corners' relative covariance (mean
// variance per pixel axis 1), sigma^2 the corner noise per pixel axis. S: the detector fits a line
// to each tag edge and takes the corners as the lines' intersections, so the two corners on one
// edge share its line's errors: a line over L px has offset variance 1 / L (its middle) and angle
// variance 12 / L^3 (least squares, unit noise per px of edge), moving each corner along both of
// its lines' normals (corner_noise = edges). Those errors load the tag's rotation and distortion
// modes more than its shift, so they show in the residual more than they move the pose (issue 31);
// corner_noise = white (the default): S = I, the classic sigma^2 (J^T J)^-1.
// The residual's degrees of freedom: E[SSR] / sigma^2 = tr((I - H) S) = t (2N - 6 when S = I).
// A fit below the prior is pooled with it, each by its degrees of freedom (the conjugate update
// of a scaled-inverse-chi-square prior worth nu0 residuals); a fit above the prior is taken in full:
//   sigma^2 = max(SSR / t, (nu0 sigma0^2 + SSR) / (nu0 + t)),
//   nu0 = pixel_sigma_dof, sigma0 = pixel_sigma_px.
// One tag leans on the prior; nine tags on the fit. A camera noisier than its prior is covered by
// the fit; one cleaner than its prior is not held at the prior however many corners show it.
#pragma once

#include "poise/camera/detector.h"
#include "poise/camera/tag_map.h"
#include "poise/camera/tag_pose.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <string>
#include <vector>

namespace poise::camera {

/// The corners' noise model (pose.corner_noise): `white` (default): independent per corner and
/// axis; `edges`: the detector's corners are the intersections of least-squares lines fitted to
/// the tag's edges, so the two corners on one edge share its line's offset and angle errors
/// (header). `edges` is measured on the synthetic camera's renders (which use it); on real images
/// lens-model and blur errors may move a tag's corners together, which it would understate.
enum class CornerNoise { kWhite, kEdgeLines };

struct WorldPoseParams {
  /// Prior corner noise per pixel axis, px: the camera's figure (docs/CAMERA.md "Covariance": the
  /// RMS of a calibration, or of a static tag's corners over frames). 0.25 px is the safe side
  /// for a real camera (a clean render's corners are near 0.05-0.1 px).
  double pixel_sigma_px = 0.25;
  /// How many residuals the prior is worth against the fit's 2N - 6 (dimensionless, > 0): 8 = two
  /// tags' corners. Raise it when the figure is measured well, lower it to trust the fit sooner.
  double pixel_sigma_dof = 8.0;
  CornerNoise corner_noise = CornerNoise::kWhite;
  double max_reprojection_rms_px = 2.0;  ///< reject the world pose above this RMS, px
  int max_iterations = 20;             ///< Levenberg-Marquardt iterations
  /// As TagPoseParams (its defaults; the camera configuration sets both from the same keys).
  double ambiguity_ratio_max = TagPoseParams{}.ambiguity_ratio_max;
  double ambiguity_min_angle_rad = TagPoseParams{}.ambiguity_min_angle_rad;
};

void validate_world_pose_params(const WorldPoseParams& params);

/// One mapped tag's observation.
struct TagObservation {
  const MappedTag* tag = nullptr;                 ///< map entry (not owned)
  std::array<Eigen::Vector2d, 4> corners_px = zero_corners();  ///< ideal (undistorted) corners, library order
  TagPoseEstimate pose;                           ///< per-tag IPPE result (starts)
};

struct WorldPoseResult {
  bool valid = false;
  std::string reject_reason;  ///< "no_mapped_tags", "ambiguous", "reprojection", "degenerate"
  Eigen::Isometry3d T_world_camera = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();  ///< [p|theta]
  double reprojection_rms_px = 0.0;
  double ambiguity_ratio = 0.0;
  int iterations = 0;
  std::vector<int> tag_ids;  ///< tags used
};

WorldPoseResult estimate_world_pose(const std::vector<TagObservation>& observations,
                                    const cv::Matx33d& camera_matrix,
                                    const WorldPoseParams& params);

/// Propagates a camera pose + covariance to the body: T_world_body = T_world_camera *
/// T_body_camera^-1, covariance in the same [dp, dtheta] world-frame parameterisation.
void camera_to_body(const Eigen::Isometry3d& T_world_camera,
                    const Eigen::Matrix<double, 6, 6>& covariance_camera,
                    const Eigen::Isometry3d& T_body_camera, Eigen::Isometry3d* T_world_body,
                    Eigen::Matrix<double, 6, 6>* covariance_body);

}  // namespace poise::camera
