#include "poise/camera/renderer.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <limits>

namespace poise::camera {

std::array<Eigen::Vector3d, 4> tag_corners_in_tag(double size_m) {
  const double h = size_m / 2.0;
  return {Eigen::Vector3d(-h, -h, 0), Eigen::Vector3d(h, -h, 0), Eigen::Vector3d(h, h, 0),
          Eigen::Vector3d(-h, h, 0)};
}

Eigen::Isometry3d look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                          const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d y = -(up - up.dot(z) * z).normalized();
  const Eigen::Vector3d x = y.cross(z);
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear().col(0) = x;
  out.linear().col(1) = y;
  out.linear().col(2) = z;
  out.translation() = eye;
  return out;
}

SceneRenderer::SceneRenderer(const CameraIntrinsics& intrinsics, const std::string& family,
                             int supersample)
    : intrinsics_(intrinsics), layout_(tag_family_layout(family)), supersample_(supersample) {
  validate_intrinsics(intrinsics_, "renderer intrinsics");
  if (supersample_ < 1 || supersample_ > 8) {
    throw ConfigError("renderer supersample must be in [1, 8]");
  }
  const int w = intrinsics_.width_px * supersample_;
  const int h = intrinsics_.height_px * supersample_;
  std::vector<cv::Point2f> samples;
  samples.reserve(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  const double step = 1.0 / supersample_;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      // Sample centres spread evenly over the pixel whose centre is the integer coordinate.
      samples.emplace_back(static_cast<float>((u + 0.5) * step - 0.5),
                           static_cast<float>((v + 0.5) * step - 0.5));
    }
  }
  if (intrinsics_.has_distortion()) {
    cv::undistortPoints(samples, rays_, intrinsics_.camera_matrix(), intrinsics_.distortion_mat(),
                        cv::noArray(), cv::noArray(),
                        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 40,
                                         1e-9));
  } else {
    // Pinhole inverse in closed form.
    rays_.resize(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const double y = (static_cast<double>(samples[i].y) - intrinsics_.cy_px) / intrinsics_.fy_px;
      const double x = (static_cast<double>(samples[i].x) - intrinsics_.cx_px - intrinsics_.skew * y) / intrinsics_.fx_px;
      rays_[i] = cv::Point2f(static_cast<float>(x), static_cast<float>(y));
    }
  }
}

cv::Mat SceneRenderer::render(const std::vector<SceneTag>& tags,
                              const Eigen::Isometry3d& T_world_camera,
                              const RenderOptions& options) const {
  struct PreparedTag {
    Eigen::Matrix3d R_tag_camera;
    Eigen::Vector3d camera_in_tag;
    double inv_cell;  // cells per metre
    cv::Mat pattern;
  };
  std::vector<PreparedTag> prepared;
  for (const auto& tag : tags) {
    const Eigen::Isometry3d T_tag_camera = tag.T_world_tag.inverse() * T_world_camera;
    if (T_tag_camera.translation().z() <= 0.0) {
      continue;  // the camera is behind the printed face
    }
    prepared.push_back({T_tag_camera.linear(), T_tag_camera.translation(),
                        layout_.width_at_border / tag.size_m, layout_.pattern(tag.id)});
  }
  const int s = supersample_;
  const int w = intrinsics_.width_px;
  const int h = intrinsics_.height_px;
  const double half = layout_.total_width / 2.0;
  const double paper_half = half + options.paper_margin_cells;
  const int total = layout_.total_width;
  cv::Mat out(h, w, CV_32FC1);
  const double norm = 1.0 / (s * s);
  for (int v = 0; v < h; ++v) {
    auto* row = out.ptr<float>(v);
    for (int u = 0; u < w; ++u) {
      double sum = 0.0;
      for (int sv = 0; sv < s; ++sv) {
        const cv::Point2f* ray_row =
            &rays_[static_cast<std::size_t>(v * s + sv) * static_cast<std::size_t>(w * s) +
                   static_cast<std::size_t>(u * s)];
        for (int su = 0; su < s; ++su) {
          const Eigen::Vector3d ray(static_cast<double>(ray_row[su].x),
                                    static_cast<double>(ray_row[su].y), 1.0);
          double best_depth = std::numeric_limits<double>::infinity();
          double value = options.background + 25.0 * std::sin(3.0 * ray.x()) +
                         15.0 * std::cos(4.0 * ray.y());
          for (const auto& t : prepared) {
            const Eigen::Vector3d d = t.R_tag_camera * ray;
            if (d.z() >= 0.0) {
              continue;  // parallel to or moving away from the tag plane
            }
            const double depth = -t.camera_in_tag.z() / d.z();
            if (depth >= best_depth) {
              continue;
            }
            const double cx = (t.camera_in_tag.x() + depth * d.x()) * t.inv_cell;
            const double cy = (t.camera_in_tag.y() + depth * d.y()) * t.inv_cell;
            if (std::abs(cx) >= paper_half || std::abs(cy) >= paper_half) {
              continue;
            }
            best_depth = depth;
            const int col = static_cast<int>(std::floor(cx + half));
            const int r = static_cast<int>(std::floor(half - cy));
            if (col >= 0 && col < total && r >= 0 && r < total) {
              value = t.pattern.at<uint8_t>(r, col) != 0 ? options.white : options.black;
            } else {
              value = options.white;
            }
          }
          sum += value;
        }
      }
      row[u] = static_cast<float>(sum * norm);
    }
  }
  if (options.blur_sigma_px > 0.0) {
    cv::GaussianBlur(out, out, cv::Size(0, 0), options.blur_sigma_px);
  }
  if (options.noise_sigma > 0.0) {
    cv::RNG rng(options.seed);
    cv::Mat noise(h, w, CV_32FC1);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, options.noise_sigma);
    out += noise;
  }
  cv::Mat result;
  out.convertTo(result, CV_8UC1);  // rounds and saturates
  return result;
}

std::array<Eigen::Vector2d, 4> SceneRenderer::project_corners(
    const SceneTag& tag, const Eigen::Isometry3d& T_world_camera) const {
  const Eigen::Isometry3d T_camera_tag = T_world_camera.inverse() * tag.T_world_tag;
  std::vector<cv::Point3d> pts;
  for (const auto& c : tag_corners_in_tag(tag.size_m)) {
    const Eigen::Vector3d p = T_camera_tag * c;
    pts.emplace_back(p.x(), p.y(), p.z());
  }
  std::vector<cv::Point2d> img;
  cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), intrinsics_.camera_matrix(),
                    intrinsics_.distortion_mat(), img);
  std::array<Eigen::Vector2d, 4> out;
  for (std::size_t i = 0; i < 4; ++i) {
    out[i] = {img[i].x, img[i].y};
  }
  return out;
}

}  // namespace poise::camera
