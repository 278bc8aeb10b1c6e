// Runs the altitude filter over a simulated profile and scores it against the truth; also the
// per-sample timing for `poise bench filters`. Evaluation code, not the estimator core: the bench
// reads clocks (thread CPU time and steady_clock).
#pragma once

#include "poise/altitude/altitude_filter.h"
#include "poise/sim/altitude_sim.h"
#include "poise/bench/bench.h"

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

/// Cost of one update, ns per sample (thread CPU and wall time).
using AltitudeBenchFigures = BenchFigures;

/// Times AltitudeFilter::update over `n` simulated samples (profile "random", method of `params`),
/// best of `repeats` runs. For `poise bench filters`.
AltitudeBenchFigures bench_altitude(int n, int repeats = 3, const AltitudeParams& params = {});

}  // namespace poise
