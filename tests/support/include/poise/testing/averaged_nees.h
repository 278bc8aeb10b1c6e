// The NEES averaged over M independent runs at evaluated instants (issue 31's chi-square tests;
// the bounds: chi_square.h): a world-frame attitude error against its published covariance, in
// total (3 degrees of freedom), tilt (world x, y: 2) and heading (world z: 1). Header-only (Eigen;
// the tests that use it link poise_core).
#pragma once

#include "poise/core/consistency.h"
#include "poise/testing/chi_square.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <cstddef>
#include <cstdio>
#include <limits>
#include <vector>

namespace poise::testing {

class AveragedNees {
 public:
  /// Instants first_s, first_s + every_s, ... up to last_s (s); each sample's share 1 / runs.
  AveragedNees(double first_s, double last_s, double every_s, int runs)
      : first_s_(first_s), every_s_(every_s), runs_(runs) {
    const auto n = static_cast<size_t>((last_s - first_s) / every_s + 0.5) + 1;
    total.assign(n, 0.0);
    tilt.assign(n, 0.0);
    heading.assign(n, 0.0);
  }
  [[nodiscard]] int instants() const { return static_cast<int>(total.size()); }
  [[nodiscard]] double instant_s(int i) const { return first_s_ + i * every_s_; }
  /// Adds one run's error `e` (rad) and covariance `cov` (rad^2) at instant i.
  void add(int i, const Eigen::Vector3d& e, const Eigen::Matrix3d& cov) {
    const auto k = static_cast<size_t>(i);
    total[k] += attitude_nees(e, cov) / runs_;
    const Eigen::Vector2d et = e.head<2>();
    tilt[k] += et.dot(cov.topLeftCorner<2, 2>().ldlt().solve(et)) / runs_;
    heading[k] += e.z() * e.z() / cov(2, 2) / runs_;
  }

  /// One run: `step(sample)` takes each sample of `simu` in turn and returns whether the filter
  /// has an estimate; at each instant's first such sample `error_and_cov(sample, e, cov)` gives
  /// the world-frame error and the published covariance, added with add(). Returns the instants
  /// reached (instants() unless the scenario ended first).
  template <typename Simulator, typename Step, typename ErrorAndCov>
  int add_run(Simulator& simu, Step&& step, ErrorAndCov&& error_and_cov) {
    int next = 0;
    while (!simu.done() && next < instants()) {
      const auto s = simu.next();
      if (step(s) && s.truth.t_s >= instant_s(next)) {
        Eigen::Vector3d e;
        Eigen::Matrix3d cov;
        error_and_cov(s, e, cov);
        add(next++, e, cov);
      }
    }
    return next;
  }
  /// The instants up to until_s (s) at which `v` (total, tilt or heading) lies outside `b`.
  [[nodiscard]] int outside(const std::vector<double>& v, const AveragedNeesBounds& b,
                            double until_s = std::numeric_limits<double>::infinity()) const {
    int n = 0;
    for (int i = 0; i < instants(); ++i) {
      const double x = v[static_cast<size_t>(i)];
      n += instant_s(i) <= until_s + 1e-9 && (x < b.lo || x > b.hi) ? 1 : 0;
    }
    return n;
  }
  /// The instants at which `v` lies above `hi`.
  [[nodiscard]] int above(const std::vector<double>& v, double hi) const {
    return outside(v, AveragedNeesBounds{-std::numeric_limits<double>::infinity(), hi});
  }
  /// One line per instant: the three averages.
  void print() const {
    for (int i = 0; i < instants(); ++i) {
      const auto k = static_cast<size_t>(i);
      std::printf("t %5.1f s: averaged NEES %.3f (tilt, 2 dof, %.3f; heading, 1 dof, %.3f)\n", instant_s(i), total[k],
                  tilt[k], heading[k]);
    }
  }

  std::vector<double> total, tilt, heading;  ///< averaged over the runs, per instant

 private:
  double first_s_;
  double every_s_;
  int runs_;
};

}  // namespace poise::testing
