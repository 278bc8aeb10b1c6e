#include "poise/core/consistency.h"

#include "poise/core/attitude.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>

namespace poise {

Eigen::Vector3d world_attitude_error(const Eigen::Quaterniond& q_est, const Eigen::Quaterniond& q_true) {
  return quat_log((q_true.normalized() * q_est.normalized().conjugate()).normalized());
}

double attitude_nees(const Eigen::Vector3d& e, const Eigen::Matrix3d& p) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  if (!e.allFinite() || !p.allFinite()) {
    return kNaN;
  }
  const double scale = p.diagonal().cwiseAbs().maxCoeff();
  if (!(scale > 0.0) || (p - p.transpose()).cwiseAbs().maxCoeff() > 1e-6 * scale) {
    return kNaN;
  }
  const Eigen::LLT<Eigen::Matrix3d> llt(p);
  if (llt.info() != Eigen::Success) {
    return kNaN;  // not positive definite: REP 145's -1, a singular or indefinite matrix
  }
  const Eigen::Vector3d w = llt.matrixL().solve(e);
  return w.squaredNorm();
}

void NeesSummary::add(double nees) {
  if (std::isnan(nees)) {
    ++missing_;
  } else {
    values_.push_back(static_cast<float>(std::min(nees, 1e30)));
  }
}

void NeesSummary::merge(const NeesSummary& other) {
  values_.insert(values_.end(), other.values_.begin(), other.values_.end());
  missing_ += other.missing_;
}

double NeesSummary::median() const {
  if (values_.empty()) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  std::vector<float> v = values_;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  const double hi = v[mid];
  if (v.size() % 2 == 1) {
    return hi;
  }
  const double lo = *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid));
  return 0.5 * (lo + hi);
}

double NeesSummary::fraction_inside(double bound) const {
  if (values_.empty()) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  const auto n = std::count_if(values_.begin(), values_.end(), [bound](float x) { return static_cast<double>(x) <= bound; });
  return static_cast<double>(n) / static_cast<double>(values_.size());
}

}  // namespace poise
