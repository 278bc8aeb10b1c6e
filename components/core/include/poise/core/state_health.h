// State-health check shared by the estimator cores (issue 19): after every update a filter checks
// that its state is finite and that each covariance is one (finite variances, none negative, and
// on every kFullCheckEvery-th sample every entry finite, symmetric within a relative tolerance
// and positive semi-definite by an LDLT factorisation). An unhealthy filter resets itself to its initial state
// (it re-initialises from the next good samples), counts the reset (`state_resets` in the
// diagnostics), reports the sample's sources rejected with reason kStateResetReason, and returns
// false from update(): a NaN is never published.
//
// Cost: the per-sample part is one sum over the state and the diagonals and a sign test; the
// LDLT of a 15x15 runs once per kFullCheckEvery samples (256: 2.56 s at 100 Hz until a covariance
// that is indefinite with a non-negative diagonal is found).
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <cmath>
#include <cstdint>

namespace poise {

/// Reason reported by every source of the sample after which the state was found unhealthy.
constexpr const char* kStateResetReason = "state_reset";

/// Symmetry tolerance of the full check: |P - P^T| <= tol * max diagonal element.
constexpr double kCovarianceSymmetryTol = 1e-6;
/// PSD tolerance of the full check: the LDLT pivots D >= -tol * max diagonal element (rounding).
constexpr double kCovariancePsdTol = 1e-9;

/// The sum of a matrix's or a number's entries (all_finite()'s terms).
template <typename Derived>
[[nodiscard]] double total(const Eigen::DenseBase<Derived>& m) {
  return m.sum();
}
[[nodiscard]] inline double total(double v) { return v; }

/// True when every value is finite: one sum (a NaN or inf in any term makes it non-finite; so
/// does an overflow of the sum, which only values near 1e308 reach), no branch per entry.
template <typename... Terms>
[[nodiscard]] bool all_finite(const Terms&... terms) {
  return std::isfinite((0.0 + ... + total(terms)));
}

/// Per sample: the variances (diagonal) finite and none negative (a NaN or inf off the diagonal
/// reaches the diagonal at the next prediction, F P F^T); with `full` also every entry finite,
/// symmetric and PSD (LDLT).
template <typename Derived>
[[nodiscard]] bool covariance_ok(const Eigen::MatrixBase<Derived>& p, bool full) {
  if (!std::isfinite(p.diagonal().sum()) || !(p.diagonal().minCoeff() >= 0.0)) {
    return false;
  }
  if (!full) {
    return true;
  }
  if (!std::isfinite(p.sum())) {
    return false;
  }
  using Matrix = Eigen::Matrix<double, Derived::RowsAtCompileTime, Derived::ColsAtCompileTime>;
  const Matrix m = p;
  const double scale = m.diagonal().maxCoeff();
  if (!((m - m.transpose()).cwiseAbs().maxCoeff() <= kCovarianceSymmetryTol * scale)) {
    return false;
  }
  const Eigen::LDLT<Matrix> ldlt(0.5 * (m + m.transpose()));
  return ldlt.info() == Eigen::Success && ldlt.vectorD().minCoeff() >= -kCovariancePsdTol * scale;
}

/// The bookkeeping of the check, part of each filter's state (so set_state() restores it).
struct StateHealth {
  /// Samples between two full (symmetry + LDLT) covariance checks.
  static constexpr uint32_t kFullCheckEvery = 256;
  uint64_t resets = 0;      ///< times the filter was reset because its state was unhealthy
  uint32_t until_full = 0;  ///< samples before the next full check

  /// True when this sample's check is the full one (counts the samples down).
  bool full_due() {
    if (until_full == 0) {
      until_full = kFullCheckEvery - 1;
      return true;
    }
    --until_full;
    return false;
  }
};

/// The reset after an unhealthy update, for a filter whose state struct `s` has a StateHealth
/// `health`: `reset()` restores the initial state, then the members `kept` (counters, per-source
/// reports) and `health` are copied back from before and one reset is counted.
template <typename State, typename Reset, typename... Kept>
void reset_keeping(State& s, Reset&& reset, Kept State::*... kept) {
  const State before = s;
  reset();
  ((s.*kept = before.*kept), ...);
  s.health = before.health;
  ++s.health.resets;
}

}  // namespace poise
