// Chi-square bounds for Monte-Carlo NEES tests (issue 31: "the NEES over many samples lies inside
// the chi-square bounds"). With M independent runs of a consistent filter, the NEES of a
// d-dimensional error summed over the runs at one instant is chi-square with d M degrees of
// freedom; the average over the runs lies in [q(a/2), q(1 - a/2)] / M with probability 1 - a
// (Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking and Navigation", 2001,
// section 5.4.2). Quantiles: the Wilson-Hilferty approximation (Wilson & Hilferty, "The
// distribution of chi-square", PNAS 17, 1931), q_p(k) = k (1 - 2/(9k) + z_p sqrt(2/(9k)))^3,
// within 0.1 % of the exact quantile for k >= 30. Header-only.
#pragma once

#include <cmath>

namespace poise::testing {

inline constexpr double kZ975 = 1.959963984540054;  ///< the standard normal's 97.5 % quantile

/// The chi-square quantile for k degrees of freedom at the standard normal quantile z (Wilson-Hilferty).
inline double chi_square_quantile(double k, double z) {
  const double c = 2.0 / (9.0 * k);
  const double b = 1.0 - c + z * std::sqrt(c);
  return k * b * b * b;
}

/// The two-sided 95 % bounds of the NEES of a dim-dimensional error averaged over `runs` runs.
struct AveragedNeesBounds {
  double lo = 0.0;
  double hi = 0.0;
};

inline AveragedNeesBounds averaged_nees_bounds_95(int dim, int runs) {
  const double k = static_cast<double>(dim) * runs;
  return {chi_square_quantile(k, -kZ975) / runs, chi_square_quantile(k, kZ975) / runs};
}

}  // namespace poise::testing
