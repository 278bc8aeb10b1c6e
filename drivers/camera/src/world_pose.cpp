#include "poise/camera/world_pose.h"

#include "poise/camera/renderer.h"  // tag_corners_in_tag

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <limits>

namespace poise::camera {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

constexpr double kMinDepthM = 1e-6;          // points closer than this to the camera plane: invalid
constexpr double kLambdaStart = 1e-3;        // LM damping
constexpr double kLambdaMax = 1e10;
constexpr double kStepTolerance = 1e-12;     // stop when |delta| falls below this (m, rad)

struct Problem {
  std::vector<Eigen::Vector3d> points_world;
  std::vector<Eigen::Vector2d> pixels;
  cv::Matx33d k;
};

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Matrix3d exp_so3(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-12) {
    return Eigen::Matrix3d::Identity() + skew(w);
  }
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

/// Sum of squared residuals (px^2); +inf when a point is behind the camera. Fills J and r if given.
double evaluate(const Problem& pb, const Eigen::Isometry3d& T_world_camera, Eigen::MatrixXd* jac,
                Eigen::VectorXd* res) {
  const Eigen::Matrix3d rt = T_world_camera.linear().transpose();
  const Eigen::Vector3d p = T_world_camera.translation();
  const std::size_t n = pb.points_world.size();
  if (jac != nullptr) {
    jac->resize(static_cast<Eigen::Index>(2 * n), 6);
    res->resize(static_cast<Eigen::Index>(2 * n));
  }
  const double fx = pb.k(0, 0);
  const double s = pb.k(0, 1);
  const double fy = pb.k(1, 1);
  double ssr = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d d = pb.points_world[i] - p;
    const Eigen::Vector3d xc = rt * d;
    if (xc.z() < kMinDepthM) {
      return std::numeric_limits<double>::infinity();
    }
    const double iz = 1.0 / xc.z();
    const double x = xc.x() * iz;
    const double y = xc.y() * iz;
    const Eigen::Vector2d r(fx * x + s * y + pb.k(0, 2) - pb.pixels[i].x(),
                            fy * y + pb.k(1, 2) - pb.pixels[i].y());
    ssr += r.squaredNorm();
    if (jac != nullptr) {
      Eigen::Matrix<double, 2, 3> j_uv_xc;
      j_uv_xc << fx * iz, s * iz, -(fx * x + s * y) * iz, 0.0, fy * iz, -fy * y * iz;
      Eigen::Matrix<double, 3, 6> j_xc_delta;
      j_xc_delta.leftCols<3>() = -rt;
      j_xc_delta.rightCols<3>() = rt * skew(d);
      const auto row = static_cast<Eigen::Index>(2 * i);
      jac->block<2, 6>(row, 0) = j_uv_xc * j_xc_delta;
      res->segment<2>(row) = r;
    }
  }
  return ssr;
}

Eigen::Isometry3d apply_delta(const Eigen::Isometry3d& t, const Vector6d& delta) {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.translation() = t.translation() + delta.head<3>();
  out.linear() = exp_so3(delta.tail<3>()) * t.linear();
  return out;
}

/// Levenberg-Marquardt from `start`; returns the refined pose, its SSR and the iterations used.
Eigen::Isometry3d refine(const Problem& pb, const Eigen::Isometry3d& start, int max_iterations,
                         double* ssr_out, int* iterations) {
  Eigen::Isometry3d t = start;
  Eigen::MatrixXd jac;
  Eigen::VectorXd res;
  double ssr = evaluate(pb, t, &jac, &res);
  double lambda = kLambdaStart;
  int it = 0;
  for (; it < max_iterations && std::isfinite(ssr); ++it) {
    const Matrix6d h = jac.transpose() * jac;
    const Vector6d g = jac.transpose() * res;
    bool improved = false;
    bool converged = false;
    while (lambda < kLambdaMax) {
      Matrix6d damped = h;
      damped.diagonal() += lambda * h.diagonal().cwiseMax(1e-12);
      const Vector6d delta = damped.ldlt().solve(-g);
      const Eigen::Isometry3d candidate = apply_delta(t, delta);
      const double c = evaluate(pb, candidate, nullptr, nullptr);
      if (c < ssr) {
        t = candidate;
        converged = delta.norm() < kStepTolerance || (ssr - c) < 1e-15 * (1.0 + ssr);
        lambda = std::max(lambda * 0.1, 1e-12);
        improved = true;
        break;
      }
      lambda *= 10.0;
    }
    if (!improved) {
      break;
    }
    ssr = evaluate(pb, t, &jac, &res);
    if (converged) {
      ++it;
      break;
    }
  }
  *ssr_out = ssr;
  *iterations = it;
  return t;
}

/// Relative covariance (8x8, [x0 y0 x1 y1 ...]) of one tag's four corners when they are the
/// intersections of its four edge lines, each fitted by least squares to its edge (header): a line
/// over L px has offset variance 1 / L at its middle and angle variance 12 / L^3 (unit noise per
/// px of edge); a corner moves along both lines' normals.
Eigen::Matrix<double, 8, 8> edge_line_corner_covariance(const Eigen::Vector2d* px) {
  Eigen::Matrix<double, 8, 8> a = Eigen::Matrix<double, 8, 8>::Zero();  // [o0 a0 o1 a1 ...] -> corners
  Eigen::Matrix<double, 8, 1> var;
  std::array<Eigen::Vector2d, 4> normal;
  std::array<Eigen::Vector2d, 4> middle;
  for (std::size_t k = 0; k < 4; ++k) {
    const Eigen::Vector2d d = px[(k + 1) % 4] - px[k];
    const double len = std::max(d.norm(), 1.0);
    normal[k] = Eigen::Vector2d(-d.y(), d.x()) / len;
    middle[k] = 0.5 * (px[k] + px[(k + 1) % 4]);
    var(static_cast<Eigen::Index>(2 * k)) = 1.0 / len;
    var(static_cast<Eigen::Index>(2 * k + 1)) = 12.0 / (len * len * len);
  }
  for (std::size_t i = 0; i < 4; ++i) {
    Eigen::Matrix2d m;
    Eigen::Matrix<double, 2, 8> rows = Eigen::Matrix<double, 2, 8>::Zero();
    const std::size_t edges[2] = {(i + 3) % 4, i};  // the two lines through corner i
    for (Eigen::Index j = 0; j < 2; ++j) {
      const std::size_t e = edges[j];
      m.row(j) = normal[e].transpose();
      const Eigen::Vector2d along(-normal[e].y(), normal[e].x());  // along the edge
      rows(j, static_cast<Eigen::Index>(2 * e)) = 1.0;              // offset at the middle
      rows(j, static_cast<Eigen::Index>(2 * e + 1)) = (px[i] - middle[e]).dot(along);  // angle
    }
    a.block<2, 8>(static_cast<Eigen::Index>(2 * i), 0) = m.inverse() * rows;
  }
  return a * var.asDiagonal() * a.transpose();
}

}  // namespace

void validate_world_pose_params(const WorldPoseParams& p) {
  if (!(p.pixel_sigma_px > 0.0 && p.pixel_sigma_px < 100.0)) {
    throw ConfigError("pose.pixel_sigma_px must be in (0, 100) px");
  }
  if (!(p.pixel_sigma_dof > 0.0 && p.pixel_sigma_dof <= 1e6)) {
    throw ConfigError("pose.pixel_sigma_dof must be in (0, 1e6] (residual degrees of freedom)");
  }
  if (!(p.max_reprojection_rms_px > 0.0)) {
    throw ConfigError("pose.max_world_reprojection_px must be positive");
  }
  if (p.max_iterations < 1 || p.max_iterations > 1000) {
    throw ConfigError("pose.max_iterations must be in [1, 1000]");
  }
}

// not split: one estimate in its order (hypotheses per tag, consensus, refinement, ambiguity test)
// over shared observation arrays.
WorldPoseResult estimate_world_pose(const std::vector<TagObservation>& observations,
                                    const cv::Matx33d& camera_matrix,
                                    const WorldPoseParams& params) {
  WorldPoseResult out;
  Problem pb;
  pb.k = camera_matrix;
  std::vector<Eigen::Isometry3d> starts;
  for (const auto& obs : observations) {
    if (obs.tag == nullptr || !std::isfinite(obs.pose.best.reprojection_rms_px) ||
        obs.pose.reprojection_too_large) {
      continue;  // not mapped, or corners that no square explains: not used
    }
    const auto corners = tag_corners_in_tag(obs.tag->size_m);
    for (std::size_t i = 0; i < 4; ++i) {
      pb.points_world.push_back(obs.tag->T_world_tag * corners[i]);
      pb.pixels.push_back(obs.corners_px[i]);
    }
    out.tag_ids.push_back(obs.tag->id);
    starts.push_back(obs.tag->T_world_tag * obs.pose.best.T_camera_tag.inverse());
    if (std::isfinite(obs.pose.second.reprojection_rms_px)) {
      starts.push_back(obs.tag->T_world_tag * obs.pose.second.T_camera_tag.inverse());
    }
  }
  if (pb.points_world.empty()) {
    out.reject_reason = "no_mapped_tags";
    return out;
  }
  // Order the starts by their joint cost.
  std::vector<std::pair<double, std::size_t>> ranked;
  for (std::size_t i = 0; i < starts.size(); ++i) {
    ranked.emplace_back(evaluate(pb, starts[i], nullptr, nullptr), i);
  }
  std::sort(ranked.begin(), ranked.end());
  const double best_start_cost = ranked.empty() ? std::numeric_limits<double>::infinity()
                                                : ranked[0].first;
  if (!std::isfinite(best_start_cost)) {
    out.reject_reason = "degenerate";
    return out;
  }
  double ssr = 0.0;
  int iterations = 0;
  Eigen::Isometry3d best = refine(pb, starts[ranked[0].second], params.max_iterations, &ssr,
                                  &iterations);
  const TagObservation* single = nullptr;
  for (const auto& obs : observations) {
    if (obs.tag != nullptr && obs.tag->id == out.tag_ids.front()) {
      single = &obs;
    }
  }
  if (out.tag_ids.size() == 1 && single != nullptr) {
    // One square: its two IPPE solutions are the two local minima; the tag's own ratio applies.
    if (single->pose.solutions_angle_rad > params.ambiguity_min_angle_rad) {
      out.ambiguity_ratio = single->pose.ambiguity_ratio;
    }
    ranked.resize(1);  // no competitor search
  }
  // The best start that is a genuinely different attitude: the competing local minimum.
  for (std::size_t k = 1; k < ranked.size(); ++k) {
    const auto& cand = starts[ranked[k].second];
    if (!std::isfinite(ranked[k].first) ||
        rotation_angle_between(cand.linear(), best.linear()) <= params.ambiguity_min_angle_rad) {
      continue;
    }
    double ssr_alt = 0.0;
    int it_alt = 0;
    const Eigen::Isometry3d alt = refine(pb, cand, params.max_iterations, &ssr_alt, &it_alt);
    if (rotation_angle_between(alt.linear(), best.linear()) > params.ambiguity_min_angle_rad &&
        std::isfinite(ssr_alt)) {
      if (ssr_alt < ssr) {
        std::swap(ssr, ssr_alt);
        best = alt;
        iterations = it_alt;
      }
      out.ambiguity_ratio = ssr_alt > 0.0 ? std::sqrt(ssr / ssr_alt) : 1.0;
    }
    break;
  }
  out.T_world_camera = best;
  out.iterations = iterations;
  const auto n = static_cast<double>(pb.points_world.size());
  out.reprojection_rms_px = std::sqrt(ssr / n);
  Eigen::MatrixXd jac;
  Eigen::VectorXd res;
  evaluate(pb, best, &jac, &res);
  const Matrix6d h = jac.transpose() * jac;
  Eigen::FullPivLU<Matrix6d> lu(h);
  if (lu.rank() < 6) {
    out.reject_reason = "degenerate";
    return out;
  }
  // The corners' relative covariance S (mean variance per pixel axis 1): white, or the edge
  // lines' (header). The pose's: (J^T J)^-1 J^T S J (J^T J)^-1; the residual's degrees of freedom
  // E[SSR] / sigma^2 = tr((I - H) S) = tr(S) - tr((J^T J)^-1 J^T S J) (2N - 6 when S = I).
  const Matrix6d h_inv = lu.inverse();
  Matrix6d pose_relative = h_inv;
  double dof = 2.0 * n - 6.0;
  if (params.corner_noise == CornerNoise::kEdgeLines) {
    Eigen::MatrixXd s = Eigen::MatrixXd::Zero(jac.rows(), jac.rows());
    for (Eigen::Index t = 0; t + 8 <= s.rows(); t += 8) {
      s.block<8, 8>(t, t) = edge_line_corner_covariance(&pb.pixels[static_cast<std::size_t>(t / 2)]);
    }
    s *= static_cast<double>(s.rows()) / s.trace();
    const Matrix6d jsj = jac.transpose() * s * jac;
    pose_relative = h_inv * jsj * h_inv;
    dof = s.trace() - (h_inv * jsj).trace();
  }
  // The prior pooled with the fit, each by its degrees of freedom; a fit above the prior in full
  // (header). N >= 4, so dof > 0.
  dof = std::max(dof, 1e-9);
  const double nu0 = params.pixel_sigma_dof;
  const double sigma2 = std::max(
      ssr / dof, (nu0 * params.pixel_sigma_px * params.pixel_sigma_px + ssr) / (nu0 + dof));
  out.covariance = sigma2 * pose_relative;
  out.covariance = 0.5 * (out.covariance + out.covariance.transpose()).eval();
  if (!out.covariance.allFinite()) {
    out.reject_reason = "degenerate";  // e.g. a quad too thin for its edge lines: never a NaN published
    return out;
  }
  if (out.ambiguity_ratio > params.ambiguity_ratio_max) {
    out.reject_reason = "ambiguous";
    return out;
  }
  if (out.reprojection_rms_px > params.max_reprojection_rms_px) {
    out.reject_reason = "reprojection";
    return out;
  }
  out.valid = true;
  return out;
}

void camera_to_body(const Eigen::Isometry3d& T_world_camera,
                    const Eigen::Matrix<double, 6, 6>& covariance_camera,
                    const Eigen::Isometry3d& T_body_camera, Eigen::Isometry3d* T_world_body,
                    Eigen::Matrix<double, 6, 6>* covariance_body) {
  const Eigen::Isometry3d T_camera_body = T_body_camera.inverse();
  *T_world_body = T_world_camera * T_camera_body;
  // p_wb = p_wc + R_wc p_cb: a world-frame rotation dtheta of the camera moves the body origin by
  // dtheta x (R_wc p_cb); the attitude error is the same rotation.
  const Eigen::Vector3d lever = T_world_camera.linear() * T_camera_body.translation();
  Matrix6d j = Matrix6d::Identity();
  j.block<3, 3>(0, 3) = -skew(lever);
  *covariance_body = j * covariance_camera * j.transpose();
}

}  // namespace poise::camera
