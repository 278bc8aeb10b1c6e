// Runs the vehicle estimator (TRIAD alone, EKF alone, switched) over a simulated case of paper 001
// and scores it against the truth; the per-sample timing for `poise bench filters`.
#pragma once

#include "poise/bench/bench.h"
#include "poise/vehicle/vehicle_estimator.h"
#include "poise/sim/vehicle_sim.h"

#include <cstdint>
#include <string>

namespace poise {

/// Roll, pitch, yaw figures in degrees.
struct Rpy {
  double roll_deg = 0.0;
  double pitch_deg = 0.0;
  double yaw_deg = 0.0;
};

struct VehicleScore {
  std::string scenario;
  std::string mode;
  std::size_t samples = 0;
  Rpy rmse;                    ///< over every valid output sample
  Rpy rmse_lateral;            ///< over samples with |lateral accel| > 1 m/s^2 (manoeuvres); 0 if none
  std::size_t lateral_samples = 0;
  Rpy final_abs_error;         ///< mean |error| over the last 2 s (standing still after the stop)
  Rpy driving_end_abs_error;   ///< mean |error| over the 2 s before braking starts (steady driving)
  double mean_roll_error_on_bank_deg = 0.0;  ///< mean (est - true) roll while driving with |bank| > 15 deg
  std::size_t bank_samples = 0;
  double triad_fraction = 0.0; ///< share of outputs that came from TRIAD
  VehicleRejects rejects;
};

/// Simulates `sim` and runs an estimator with `params` (its mode decides TRIAD/EKF/switched).
VehicleScore score_vehicle(const VehicleSimConfig& sim, const VehicleParams& params);

/// Cost of one update, ns per sample: thread CPU time and wall time.
using VehicleBenchFigures = BenchFigures;

/// Times VehicleEstimator::update over `n` samples of the mountain_road case (mode of `params`,
/// switched by default), best of `repeats` runs. For `poise bench filters`.
VehicleBenchFigures bench_vehicle(int n, int repeats = 3, const VehicleParams& params = {});

}  // namespace poise
