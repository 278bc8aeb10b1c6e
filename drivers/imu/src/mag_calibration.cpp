#include "poise/imu/mag_calibration.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>

namespace poise::imu {

EllipsoidFit fit_ellipsoid(const std::vector<Eigen::Vector3d>& points, double field_ut) {
  EllipsoidFit fit;
  fit.points = points.size();
  if (points.size() < 9) {
    fit.error = "need at least 9 magnetometer samples (got " + std::to_string(points.size()) + ")";
    return fit;
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  double scale = 0;
  for (const auto& p : points) scale += (p - mean).norm();
  scale /= static_cast<double>(points.size());
  if (!(scale > 1e-9)) {
    fit.error = "all magnetometer samples are identical: is the magnetometer working?";
    return fit;
  }
  const auto n = static_cast<Eigen::Index>(points.size());
  Eigen::MatrixXd d(n, 9);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d q = (points[static_cast<std::size_t>(i)] - mean) / scale;
    d.row(i) << q.x() * q.x(), q.y() * q.y(), q.z() * q.z(), 2 * q.y() * q.z(), 2 * q.x() * q.z(),
        2 * q.x() * q.y(), 2 * q.x(), 2 * q.y(), 2 * q.z();
  }
  const Eigen::VectorXd v = d.colPivHouseholderQr().solve(Eigen::VectorXd::Ones(n));
  Eigen::Matrix3d m;
  m << v(0), v(5), v(4), v(5), v(1), v(3), v(4), v(3), v(2);
  const Eigen::Vector3d nn(v(6), v(7), v(8));
  if (std::abs(m.determinant()) < 1e-12) {
    fit.error = "the samples do not span an ellipsoid: rotate the sensor through all orientations";
    return fit;
  }
  const Eigen::Vector3d c = -m.inverse() * nn;
  const double k = 1.0 + c.dot(m * c);
  const Eigen::Matrix3d e = m / k;  // normalised coordinates
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(e);
  if (es.info() != Eigen::Success || es.eigenvalues().minCoeff() <= 0) {
    fit.error = "the fitted surface is not an ellipsoid: rotate the sensor through more orientations";
    return fit;
  }
  // Back to uT: center = mean + scale c, E_ut = E / scale^2 (eigenvalues / scale^2).
  fit.hard_iron_ut = mean + scale * c;
  const Eigen::Vector3d lambda = es.eigenvalues() / (scale * scale);
  Eigen::Vector3d radii = lambda.cwiseSqrt().cwiseInverse();
  std::sort(radii.data(), radii.data() + 3);
  fit.radii_ut = radii;
  fit.field_ut = field_ut > 0 ? field_ut : std::cbrt(radii.prod());
  const Eigen::Matrix3d sqrt_e =
      es.eigenvectors() * lambda.cwiseSqrt().asDiagonal() * es.eigenvectors().transpose();
  fit.soft_iron = fit.field_ut * sqrt_e;
  double ss = 0;
  double before_mean = 0;
  for (const auto& p : points) before_mean += (p - mean).norm();
  before_mean /= static_cast<double>(points.size());
  double ss_before = 0;
  for (const auto& p : points) {
    const double r = (fit.soft_iron * (p - fit.hard_iron_ut)).norm() - fit.field_ut;
    ss += r * r;
    const double rb = (p - mean).norm() - before_mean;
    ss_before += rb * rb;
  }
  fit.residual_rms_ut = std::sqrt(ss / static_cast<double>(points.size()));
  fit.spread_before_ut = std::sqrt(ss_before / static_cast<double>(points.size()));
  fit.ok = true;
  return fit;
}

SphereCoverage::SphereCoverage(int bins) {
  const double golden = 3.14159265358979323846 * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < bins; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / bins;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = golden * i;
    centers_.emplace_back(r * std::cos(phi), r * std::sin(phi), z);
  }
  hit_.assign(centers_.size(), false);
}

void SphereCoverage::clear() {
  hit_.assign(centers_.size(), false);
  hits_ = 0;
}

void SphereCoverage::add(const Eigen::Vector3d& direction) {
  const double norm = direction.norm();
  if (!(norm > 0)) return;
  const Eigen::Vector3d u = direction / norm;
  std::size_t best = 0;
  double best_dot = -2;
  for (std::size_t i = 0; i < centers_.size(); ++i) {
    const double dd = centers_[i].dot(u);
    if (dd > best_dot) {
      best_dot = dd;
      best = i;
    }
  }
  if (!hit_[best]) {
    hit_[best] = true;
    ++hits_;
  }
}

double SphereCoverage::fraction() const {
  return centers_.empty() ? 0.0 : static_cast<double>(hits_) / static_cast<double>(centers_.size());
}

CalibrationSession::CalibrationSession(const CalibrationParams& p) : params_(p) {}

void CalibrationSession::skip_still() {
  if (phase_ == Phase::kStill) phase_ = Phase::kRotate;
}

void CalibrationSession::update_still(const RawSample& s, int64_t sensor_ns) {
  still_.push_back({sensor_ns, s.gyro_rps, s.accel_mps2.norm()});
  const auto window_ns = static_cast<int64_t>(params_.still_s * 1e9);
  while (!still_.empty() && still_.front().t < sensor_ns - window_ns) still_.pop_front();
  // Statistics over the last second decide whether the sensor moves.
  const int64_t recent_ns = std::min<int64_t>(window_ns, 1'000'000'000);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d sq = Eigen::Vector3d::Zero();
  double an = 0;
  double an2 = 0;
  std::size_t k = 0;
  for (auto it = still_.rbegin(); it != still_.rend() && it->t >= sensor_ns - recent_ns; ++it) {
    mean += it->gyro;
    sq += it->gyro.cwiseProduct(it->gyro);
    an += it->accel_norm;
    an2 += it->accel_norm * it->accel_norm;
    ++k;
  }
  if (k < 10) return;
  const double kk = static_cast<double>(k);
  const Eigen::Vector3d var = (sq / kk - (mean / kk).cwiseProduct(mean / kk)).cwiseMax(0.0);
  const double avar = std::max(0.0, an2 / kk - (an / kk) * (an / kk));
  moving_ = std::sqrt(var.maxCoeff()) > params_.gyro_still_std_rps ||
            std::sqrt(avar) > params_.accel_still_std_mps2;
  if (moving_) {
    still_.clear();  // the still period must be continuous: start over
    return;
  }
  if (still_.size() >= 2 && still_.back().t - still_.front().t >= window_ns - window_ns / 100) {
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (const auto& it : still_) m += it.gyro;
    m /= static_cast<double>(still_.size());
    double v = 0;
    for (const auto& it : still_) v += (it.gyro - m).squaredNorm();
    gyro_bias_ = m;
    gyro_noise_ = std::sqrt(v / (3.0 * static_cast<double>(still_.size())));
    has_gyro_bias_ = true;
    phase_ = Phase::kRotate;
  }
}

void CalibrationSession::update_coverage() {
  if (mag_.size() < 10) return;
  Eigen::Vector3d lo = mag_[0];
  Eigen::Vector3d hi = mag_[0];
  for (const auto& p : mag_) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector3d center = 0.5 * (lo + hi);
  coverage_.clear();
  for (const auto& p : mag_) coverage_.add(p - center);
  coverage_fraction_ = coverage_.fraction();
  coverage_at_ = mag_.size();
  if (mag_.size() >= 30) {
    const EllipsoidFit f = fit_ellipsoid(mag_);
    provisional_residual_ = f.ok ? f.residual_rms_ut : 0.0;
  }
}

void CalibrationSession::add(const RawSample& s, int64_t sensor_ns) {
  switch (phase_) {
    case Phase::kStill:
      update_still(s, sensor_ns);
      return;
    case Phase::kRotate:
      break;
    case Phase::kDone:
      return;
  }
  if (!s.has_mag) return;
  if (mag_.empty() || (s.mag_ut - mag_.back()).norm() >= params_.min_mag_spacing_ut) {
    if (mag_.size() < params_.max_mag_points) mag_.push_back(s.mag_ut);
  }
  if (mag_.size() >= coverage_at_ + 25) update_coverage();  // amortised: every 25 new points
  if (mag_.size() >= params_.min_mag_points && coverage_fraction_ >= params_.coverage_target) {
    finish();
  }
}

void CalibrationSession::finish() {
  if (phase_ == Phase::kDone) return;
  fit_ = fit_ellipsoid(mag_);
  phase_ = Phase::kDone;
}

CalibrationSession::Progress CalibrationSession::progress() const {
  Progress p;
  p.phase = phase_;
  if (!still_.empty()) {
    p.still_fraction = std::min(
        1.0, static_cast<double>(still_.back().t - still_.front().t) / (params_.still_s * 1e9));
  }
  if (has_gyro_bias_) p.still_fraction = 1.0;
  p.moving = moving_;
  p.coverage = coverage_fraction_;
  p.mag_points = mag_.size();
  p.residual_ut = phase_ == Phase::kDone && fit_.ok ? fit_.residual_rms_ut : provisional_residual_;
  return p;
}

}  // namespace poise::imu
