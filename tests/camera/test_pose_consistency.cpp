// The published world-pose covariance against the error over many frames of the synthetic camera's
// floor scene (sim_camera's geometry: 3x3 tags of 24 cm, 0.7 m apart, 1.2 m below, 640x480,
// f = 460 px), corners projected from known poses with white noise of a known sigma. Oracle: the
// poses the corners come from; the NEES of an honest covariance is chi-square distributed.
#include "camera_test_util.h"

#include "poise/camera/world_pose.h"

#include <Eigen/LU>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

namespace poise::camera {
namespace {

using namespace poise::camera::testing;

constexpr uint64_t kSeed = 20261127;

CameraIntrinsics sim_camera_intrinsics() {
  CameraIntrinsics k;
  k.width_px = 640;
  k.height_px = 480;
  k.fx_px = k.fy_px = 460.0;
  k.cx_px = (640 - 1) / 2.0;
  k.cy_px = (480 - 1) / 2.0;
  return k;
}

std::vector<SceneTag> floor_tags() {
  std::vector<SceneTag> tags;
  int id = 0;
  for (int i = -1; i <= 1; ++i) {
    for (int j = -1; j <= 1; ++j) {
      SceneTag t;
      t.id = id++;
      t.size_m = 0.24;
      t.T_world_tag.translation() = Eigen::Vector3d(i * 0.7, j * 0.7, -1.2);
      tags.push_back(t);
    }
  }
  return tags;
}

Eigen::Vector3d log_so3(const Eigen::Matrix3d& r) {
  const Eigen::AngleAxisd aa(r);
  return aa.angle() * aa.axis();
}

/// A camera over the floor scene looking down: any heading, tilted up to 0.2 rad, within 0.8 m of
/// the centre horizontally and 0.3 m of the start height (1-9 tags in view).
Eigen::Isometry3d random_floor_camera(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Isometry3d cam = Eigen::Isometry3d::Identity();
  cam.linear() = (Eigen::AngleAxisd(3.14159 * u(rng), Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(0.2 * u(rng), Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(kPi + 0.2 * u(rng), Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
  cam.translation() = Eigen::Vector3d(0.8 * u(rng), 0.8 * u(rng), 0.3 * u(rng));
  return cam;
}

/// The tag's corners projected from `cam` without noise into `px`; false when one is behind the
/// camera or not more than `margin_px` inside the image.
bool project_tag(const CameraIntrinsics& k, const Eigen::Isometry3d& cam, const MappedTag& tag,
                 const std::array<Eigen::Vector3d, 4>& corners_in_tag, double margin_px,
                 std::array<Eigen::Vector2d, 4>& px) {
  bool inside = true;
  for (std::size_t i = 0; i < 4; ++i) {
    const Eigen::Vector3d xc = cam.inverse() * (tag.T_world_tag * corners_in_tag[i]);
    px[i] = Eigen::Vector2d(k.fx_px * xc.x() / xc.z() + k.cx_px, k.fy_px * xc.y() / xc.z() + k.cy_px);
    inside = inside && xc.z() > 0.0 && px[i].x() > margin_px && px[i].x() < k.width_px - margin_px &&
             px[i].y() > margin_px && px[i].y() < k.height_px - margin_px;
  }
  return inside;
}

/// The 6-dof NEES of an estimated world pose against the true camera pose [dp, dtheta].
double pose_nees(const Eigen::Isometry3d& cam, const WorldPoseResult& r) {
  Eigen::Matrix<double, 6, 1> e;
  e.head<3>() = cam.translation() - r.T_world_camera.translation();
  e.tail<3>() = log_so3(cam.linear() * r.T_world_camera.linear().transpose());
  return e.dot(r.covariance.inverse() * e);
}

// Corners with white Gaussian noise of a known sigma (no rendering): the covariance's model.
constexpr double kWhiteCornerSigmaPx = 0.08;
constexpr int kWhiteFrames = 300;
// Two-sided 99 % bounds of the mean of kWhiteFrames chi-square(6) draws (chi-square with 1800 dof
// over 300: 1800 -+ 2.576 sqrt(3600), Wilson-Hilferty within 0.5 %).
constexpr double kNeesMeanLow = 5.38;
constexpr double kNeesMeanHigh = 6.62;
// sigma^2 is estimated per frame (the fit's SSR pooled with the prior): E[sigma^2 / sigma_hat^2]
// exceeds 1 by about 2 dof / (nu0 + dof)^2, at most 6.25 % (dof = nu0 = 8).
constexpr double kEstimatedSigmaAllowance = 1.07;

// GIVEN the floor scene's corners projected from known camera poses (1-9 tags in view) with white
//   Gaussian noise of 0.08 px per axis, and a prior pixel_sigma_px of 1x and 3x that noise
// WHEN the world pose and its covariance are estimated
// THEN the 6-dof NEES, scaled by the closed-form expectation of the pooled sigma^2 over the true
//   one, (nu0 k^2 + dof) / (nu0 + dof) with k = prior / noise, averages inside the chi-square
//   bounds (with the 3x prior that factor is 7.4 with one tag to 1.9 with nine, where the old
//   floor, max(prior, fit), kept 9 whatever their number; with the 1x prior, the max() with the
//   fit raises sigma^2 a little above the pooled value). Measured: 6.01 (1x), 5.98 (3x; unscaled
//   1.49, the old floor would give about 6 / 9 = 0.67).
TEST(WorldPoseConsistency, GivenCornersWithKnownWhiteNoiseWhenEstimatedThenNeesMatchesThePooledSigma) {
  const CameraIntrinsics k = sim_camera_intrinsics();
  const std::vector<SceneTag> scene = floor_tags();
  const TagMap map = map_of(scene);
  const cv::Matx33d kmat(k.fx_px, 0.0, k.cx_px, 0.0, k.fy_px, k.cy_px, 0.0, 0.0, 1.0);
  const auto corners_in_tag = tag_corners_in_tag(0.24);
  for (const double k_prior : {1.0, 3.0}) {
    WorldPoseParams params;
    params.corner_noise = CornerNoise::kWhite;
    params.pixel_sigma_px = k_prior * kWhiteCornerSigmaPx;
    std::mt19937_64 rng(kSeed + static_cast<uint64_t>(k_prior));
    std::normal_distribution<double> noise(0.0, kWhiteCornerSigmaPx);
    double scaled_sum = 0.0;
    double raw_sum = 0.0;
    int frames = 0;
    while (frames < kWhiteFrames) {
      const Eigen::Isometry3d cam = random_floor_camera(rng);
      std::vector<TagObservation> obs;
      for (const auto& [id, tag] : map.tags) {
        TagObservation o;
        o.tag = &tag;
        const bool inside = project_tag(k, cam, tag, corners_in_tag, 0.0, o.corners_px);
        for (Eigen::Vector2d& c : o.corners_px) {
          c.x() += noise(rng);
          c.y() += noise(rng);
        }
        o.pose.best.T_camera_tag = cam.inverse() * tag.T_world_tag;  // start: the truth
        o.pose.second.reprojection_rms_px = std::numeric_limits<double>::quiet_NaN();
        if (inside) obs.push_back(o);
      }
      if (obs.empty()) continue;
      const WorldPoseResult r = estimate_world_pose(obs, kmat, params);
      ASSERT_TRUE(r.valid) << r.reject_reason;
      const double nees = pose_nees(cam, r);
      ASSERT_TRUE(std::isfinite(nees));
      const double dof = 8.0 * static_cast<double>(obs.size()) - 6.0;
      const double nu0 = params.pixel_sigma_dof;
      raw_sum += nees;
      scaled_sum += nees * (nu0 * k_prior * k_prior + dof) / (nu0 + dof);
      ++frames;
    }
    const double scaled = scaled_sum / frames;
    const double raw = raw_sum / frames;
    std::printf("prior %.0fx the noise: NEES mean %.2f, scaled by the pooled closed form %.2f "
                "(seed %llu)\n", k_prior, raw, scaled,
                static_cast<unsigned long long>(kSeed + static_cast<uint64_t>(k_prior)));
    EXPECT_GT(scaled, kNeesMeanLow);
    EXPECT_LT(scaled, kNeesMeanHigh * kEstimatedSigmaAllowance);
  }
}

// The detector's corner model, simulated independently of the estimator's formula: each projected
// edge sampled once per pixel of its length, each sample displaced across the edge by white noise,
// a least-squares line fitted (offset + slope), the corner the intersection of its two lines.
constexpr double kEdgeSampleSigmaPx = 0.25;  // noise of one edge sample across the edge, px
constexpr int kEdgeFrames = 300;

struct EdgeFitCorners {
  std::array<Eigen::Vector2d, 4> corners;
  double mean_axis_variance_px2 = 0.0;  // the exact per-axis corner variance of this fit, averaged
};

EdgeFitCorners corners_from_fitted_edges(const std::array<Eigen::Vector2d, 4>& truth, double sigma,
                                         std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, sigma);
  std::array<Eigen::Vector2d, 4> normal;
  std::array<Eigen::Vector2d, 4> along;
  std::array<Eigen::Vector2d, 4> middle;
  std::array<double, 4> offset{};
  std::array<double, 4> slope{};
  std::array<double, 4> samples{};
  std::array<double, 4> sum_s2{};
  for (std::size_t k = 0; k < 4; ++k) {
    const Eigen::Vector2d d = truth[(k + 1) % 4] - truth[k];
    const double len = d.norm();
    along[k] = d / len;
    normal[k] = Eigen::Vector2d(-along[k].y(), along[k].x());
    middle[k] = 0.5 * (truth[k] + truth[(k + 1) % 4]);
    const int n = std::max(2, static_cast<int>(std::lround(len)));
    double sy = 0.0;
    double ssy = 0.0;
    double ss = 0.0;
    for (int j = 0; j < n; ++j) {
      const double sj = -0.5 * len + (j + 0.5) * len / n;  // symmetric: offset and slope independent
      const double y = noise(rng);
      sy += y;
      ssy += sj * y;
      ss += sj * sj;
    }
    offset[k] = sy / n;
    slope[k] = ssy / ss;
    samples[k] = n;
    sum_s2[k] = ss;
  }
  EdgeFitCorners out;
  for (std::size_t i = 0; i < 4; ++i) {
    const std::size_t e[2] = {(i + 3) % 4, i};
    Eigen::Matrix2d m;
    Eigen::Vector2d rhs;
    Eigen::Matrix2d var = Eigen::Matrix2d::Zero();
    for (Eigen::Index j = 0; j < 2; ++j) {
      const std::size_t k = e[j];
      const double s = (truth[i] - middle[k]).dot(along[k]);
      m.row(j) = normal[k].transpose();
      rhs(j) = normal[k].dot(truth[i]) + offset[k] + slope[k] * s;  // the fitted line at the corner
      var(j, j) = sigma * sigma * (1.0 / samples[k] + s * s / sum_s2[k]);
    }
    out.corners[i] = m.inverse() * rhs;
    out.mean_axis_variance_px2 += (m.inverse() * var * m.inverse().transpose()).trace() / 8.0;
  }
  return out;
}

// GIVEN the floor scene's corners projected from known camera poses (1-9 tags) and displaced as a
//   line-fitting detector displaces them (edges sampled per pixel with 0.25 px of noise across the
//   edge, least-squares lines, corners at their intersections: the two corners of an edge share its
//   line's errors), the prior pixel_sigma_px set to the frame's exact corner noise
// WHEN the world pose and its covariance are estimated with the edge-line model
// THEN the 6-dof NEES averages inside the chi-square bounds; the white model's (which takes the
//   residual for noise that moves the pose as much) averages below them.
TEST(WorldPoseConsistency, GivenCornersFromFittedEdgeLinesWhenEstimatedThenNeesMatchesTheEdgeModel) {
  const CameraIntrinsics k = sim_camera_intrinsics();
  const TagMap map = map_of(floor_tags());
  const cv::Matx33d kmat(k.fx_px, 0.0, k.cx_px, 0.0, k.fy_px, k.cy_px, 0.0, 0.0, 1.0);
  const auto corners_in_tag = tag_corners_in_tag(0.24);
  std::mt19937_64 rng(kSeed + 7);
  double edges_sum = 0.0;
  double white_sum = 0.0;
  int frames = 0;
  while (frames < kEdgeFrames) {
    const Eigen::Isometry3d cam = random_floor_camera(rng);
    std::vector<TagObservation> obs;
    double variance_sum = 0.0;
    for (const auto& [id, tag] : map.tags) {
      TagObservation o;
      o.tag = &tag;
      std::array<Eigen::Vector2d, 4> truth;
      if (!project_tag(k, cam, tag, corners_in_tag, 1.0, truth)) continue;
      const EdgeFitCorners fitted = corners_from_fitted_edges(truth, kEdgeSampleSigmaPx, rng);
      o.corners_px = fitted.corners;
      variance_sum += fitted.mean_axis_variance_px2;
      o.pose.best.T_camera_tag = cam.inverse() * tag.T_world_tag;  // start: the truth
      o.pose.second.reprojection_rms_px = std::numeric_limits<double>::quiet_NaN();
      obs.push_back(o);
    }
    if (obs.empty()) continue;
    WorldPoseParams params;
    params.pixel_sigma_px = std::sqrt(variance_sum / static_cast<double>(obs.size()));
    double nees[2] = {0.0, 0.0};
    for (const CornerNoise model : {CornerNoise::kEdgeLines, CornerNoise::kWhite}) {
      params.corner_noise = model;
      const WorldPoseResult r = estimate_world_pose(obs, kmat, params);
      ASSERT_TRUE(r.valid) << r.reject_reason;
      nees[model == CornerNoise::kWhite ? 1 : 0] = pose_nees(cam, r);
    }
    ASSERT_TRUE(std::isfinite(nees[0]) && std::isfinite(nees[1]));
    edges_sum += nees[0];
    white_sum += nees[1];
    ++frames;
  }
  const double edges = edges_sum / frames;
  const double white = white_sum / frames;
  std::printf("corners from fitted edge lines: NEES mean %.2f with the edge model, %.2f with the "
              "white model (seed %llu)\n", edges, white,
              static_cast<unsigned long long>(kSeed + 7));
  EXPECT_GT(edges, kNeesMeanLow);
  EXPECT_LT(edges, kNeesMeanHigh * kEstimatedSigmaAllowance);
  EXPECT_LT(white, kNeesMeanLow);
}

}  // namespace
}  // namespace poise::camera
