// Runs the altitude filter over a simulated profile and scores it against the truth; also the
// per-sample timing used by `poise bench filters`. Pure C++ (the bench takes the clock from the
// caller-side std::chrono, which is allowed outside estimator cores: this file is evaluation code).
#pragma once

#include "poise/altitude/altitude_filter.h"
#include "poise/altitude/altitude_sim.h"

#include <cstdint>
#include <string>

namespace poise {

struct AltitudeScore {
  std::string profile;
  std::string method;
  uint64_t seed = 0;
  std::size_t samples = 0;
  double height_rmse_m = 0.0;           ///< over every valid output sample
  double velocity_rmse_mps = 0.0;       ///< idem
  double baro_height_rmse_m = 0.0;      ///< raw barometric height vs truth (the input's quality)
  double max_abs_velocity_error_mps = 0.0;
  double stationary_fraction = 0.0;     ///< share of samples flagged stationary
  double stationary_true_fraction = 0.0;///< share of samples truly still
  AltitudeRejects rejects;
};

/// Simulates `sim` and runs a filter with `params` over it.
AltitudeScore score_altitude(const AltitudeSimConfig& sim, const AltitudeParams& params);

/// Mean wall time of AltitudeFilter::update (ns per sample) over `n` simulated samples (profile
/// "random", method of `params`). For `poise bench filters`.
double bench_altitude_ns_per_sample(int n, const AltitudeParams& params = {});

}  // namespace poise
