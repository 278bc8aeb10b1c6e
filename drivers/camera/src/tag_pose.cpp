#include "poise/camera/tag_pose.h"

#include "poise/camera/renderer.h"  // tag_corners_in_tag

#include <opencv2/calib3d.hpp>

#include <cmath>
#include <limits>
#include <vector>

namespace poise::camera {
namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Isometry3d from_rvec_tvec(const cv::Mat& rvec, const cv::Mat& tvec) {
  cv::Mat r64;
  cv::Mat t64;
  rvec.convertTo(r64, CV_64F);
  tvec.convertTo(t64, CV_64F);
  const Eigen::Vector3d r(r64.at<double>(0), r64.at<double>(1), r64.at<double>(2));
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  const double angle = r.norm();
  if (angle > 0.0) {
    out.linear() = Eigen::AngleAxisd(angle, r / angle).toRotationMatrix();
  }
  out.translation() = Eigen::Vector3d(t64.at<double>(0), t64.at<double>(1), t64.at<double>(2));
  return out;
}

double rms_reprojection(const Eigen::Isometry3d& T_camera_tag,
                        const std::array<Eigen::Vector3d, 4>& object,
                        const std::array<Eigen::Vector2d, 4>& image, const cv::Matx33d& k) {
  double sum = 0.0;
  for (std::size_t i = 0; i < 4; ++i) {
    const Eigen::Vector3d p = T_camera_tag * object[i];
    if (p.z() <= 0.0) {
      return std::numeric_limits<double>::infinity();
    }
    const double x = p.x() / p.z();
    const double y = p.y() / p.z();
    const double u = k(0, 0) * x + k(0, 1) * y + k(0, 2);
    const double v = k(1, 1) * y + k(1, 2);
    sum += (Eigen::Vector2d(u, v) - image[i]).squaredNorm();
  }
  return std::sqrt(sum / 4.0);
}

}  // namespace

void validate_tag_pose_params(const TagPoseParams& p) {
  if (!(p.ambiguity_ratio_max > 0.0 && p.ambiguity_ratio_max <= 1.0)) {
    throw ConfigError("pose.ambiguity_ratio_max must be in (0, 1]");
  }
  if (!(p.ambiguity_min_angle_rad >= 0.0 && p.ambiguity_min_angle_rad < kPi)) {
    throw ConfigError("pose.ambiguity_min_angle_deg must be in [0, 180)");
  }
  if (!(p.max_reprojection_rms_px > 0.0)) {
    throw ConfigError("pose.max_tag_reprojection_px must be positive");
  }
}

double rotation_angle_between(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

TagPoseEstimate estimate_tag_pose(const std::array<Eigen::Vector2d, 4>& corners_px, double size_m,
                                  const cv::Matx33d& camera_matrix, const TagPoseParams& params) {
  TagPoseEstimate out;
  // IPPE-square wants the object points in this order (OpenCV docs): (-h, h), (h, h), (h, -h),
  // (-h, -h). In our tag frame (y up) those are top-left, top-right, bottom-right, bottom-left:
  // libapriltag corners 3, 2, 1, 0.
  const auto object = tag_corners_in_tag(size_m);
  static constexpr std::array<std::size_t, 4> kOrder = {3, 2, 1, 0};
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (std::size_t i : kOrder) {
    obj.emplace_back(object[i].x(), object[i].y(), object[i].z());
    img.emplace_back(corners_px[i].x(), corners_px[i].y());
  }
  std::vector<cv::Mat> rvecs;
  std::vector<cv::Mat> tvecs;
  int n = 0;
  try {
    n = cv::solvePnPGeneric(obj, img, camera_matrix, cv::noArray(), rvecs, tvecs, false,
                            cv::SOLVEPNP_IPPE_SQUARE);
  } catch (const cv::Exception&) {
    n = 0;  // degenerate corners (e.g. collinear): no pose
  }
  if (n < 1) {
    out.reprojection_too_large = true;
    return out;
  }
  std::vector<TagPoseSolution> sols;
  for (int i = 0; i < n; ++i) {
    TagPoseSolution s;
    s.T_camera_tag = from_rvec_tvec(rvecs[static_cast<std::size_t>(i)],
                                    tvecs[static_cast<std::size_t>(i)]);
    s.reprojection_rms_px = rms_reprojection(s.T_camera_tag, object, corners_px, camera_matrix);
    sols.push_back(s);
  }
  if (sols.size() > 1 && sols[1].reprojection_rms_px < sols[0].reprojection_rms_px) {
    std::swap(sols[0], sols[1]);
  }
  out.best = sols[0];
  if (sols.size() > 1 && std::isfinite(sols[1].reprojection_rms_px)) {
    out.second = sols[1];
    out.ambiguity_ratio = sols[1].reprojection_rms_px > 0.0
                              ? sols[0].reprojection_rms_px / sols[1].reprojection_rms_px
                              : 1.0;
    out.solutions_angle_rad =
        rotation_angle_between(sols[0].T_camera_tag.linear(), sols[1].T_camera_tag.linear());
  } else {
    out.second = sols[0];
  }
  out.ambiguous = out.ambiguity_ratio > params.ambiguity_ratio_max &&
                  out.solutions_angle_rad > params.ambiguity_min_angle_rad;
  out.reprojection_too_large = !(out.best.reprojection_rms_px <= params.max_reprojection_rms_px);
  out.valid = !out.ambiguous && !out.reprojection_too_large;
  return out;
}

}  // namespace poise::camera
