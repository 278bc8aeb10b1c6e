// Consistency of a published attitude covariance against a known truth (issue 31).
//
// Error of an estimate: e = log(q_true (x) q_est^-1), the world-frame rotation vector (rad) that
// takes the estimate to the truth: the convention of attitude_covariance (idl/estimates.idl).
// NEES = e^T P^-1 e with P the published 3x3 covariance (rad^2). For a consistent filter NEES
// follows a chi-square law with 3 degrees of freedom: median 2.366, 95 % of samples at or below
// 7.815. The median and the fraction inside the 95 % ellipsoid are the robust figures over
// correlated samples (the mean is dominated by a few long stretches).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstddef>
#include <vector>

namespace poise {

/// chi-square, 3 degrees of freedom: the median and the 95 % quantile.
inline constexpr double kNeesMedianDof3 = 2.366;
inline constexpr double kNees95Dof3 = 7.815;

/// World-frame rotation vector of q_true (x) q_est^-1 (rad; the shorter rotation).
Eigen::Vector3d world_attitude_error(const Eigen::Quaterniond& q_est, const Eigen::Quaterniond& q_true);

/// e^T P^-1 e; NaN when P is not a finite symmetric positive-definite matrix (no covariance, an
/// all-zero one, REP 145's -1) or e is not finite.
double attitude_nees(const Eigen::Vector3d& e, const Eigen::Matrix3d& p);

/// NEES values of many samples, with the robust summary figures.
class NeesSummary {
 public:
  /// A sample's NEES; a NaN counts as a sample without a usable covariance.
  void add(double nees);
  /// Appends another summary's samples (a group of trials).
  void merge(const NeesSummary& other);
  /// Samples with a usable covariance.
  [[nodiscard]] size_t samples() const { return values_.size(); }
  /// Samples whose covariance was missing or not positive definite.
  [[nodiscard]] size_t without_covariance() const { return missing_; }
  /// Median NEES (NaN over no sample).
  [[nodiscard]] double median() const;
  /// Fraction (0..1) of the samples with a usable covariance whose NEES <= bound (NaN over none).
  [[nodiscard]] double fraction_inside(double bound = kNees95Dof3) const;

 private:
  std::vector<float> values_;  // float: tens of thousands per trial, 7 digits are plenty
  size_t missing_ = 0;
};

}  // namespace poise
