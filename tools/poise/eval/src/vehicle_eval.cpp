#include "poise/eval/vehicle_eval.h"

#include "poise/core/attitude.h"
#include "poise/bench/bench.h"

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <memory>
#include <vector>

namespace poise {
namespace {

struct Acc {
  double r = 0.0;
  double p = 0.0;
  double y = 0.0;
  std::size_t n = 0;
  void add_sq(const Eigen::Vector3d& e) {
    r += e(0) * e(0);
    p += e(1) * e(1);
    y += e(2) * e(2);
    ++n;
  }
  void add_abs(const Eigen::Vector3d& e) {
    r += std::abs(e(0));
    p += std::abs(e(1));
    y += std::abs(e(2));
    ++n;
  }
  [[nodiscard]] Rpy rms() const {
    if (n == 0) {
      return {};
    }
    const auto dn = static_cast<double>(n);
    return {std::sqrt(r / dn) * kDegPerRad, std::sqrt(p / dn) * kDegPerRad, std::sqrt(y / dn) * kDegPerRad};
  }
  [[nodiscard]] Rpy mean() const {
    if (n == 0) {
      return {};
    }
    const auto dn = static_cast<double>(n);
    return {r / dn * kDegPerRad, p / dn * kDegPerRad, y / dn * kDegPerRad};
  }
};

}  // namespace

VehicleScore score_vehicle(const VehicleSimConfig& sim, const VehicleParams& params) {
  const auto samples = simulate_vehicle(sim);
  VehicleEstimator est(params);
  VehicleScore score;
  score.scenario = sim.scenario;
  score.mode = to_string(params.mode);

  // Index where braking starts (last sample at top speed) and the final 2 s.
  double v_max = 0.0;
  for (const auto& s : samples) {
    v_max = std::max(v_max, s.true_speed_mps);
  }
  std::size_t brake_idx = 0;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    if (samples[k].true_speed_mps >= 0.999 * v_max) {
      brake_idx = k;
    }
  }
  const auto window = static_cast<std::size_t>(2.0 * sim.rate_hz);
  const std::size_t final_from = samples.size() > window ? samples.size() - window : 0;
  const std::size_t drive_from = brake_idx > window ? brake_idx - window : 0;

  Acc all;
  Acc lat;
  Acc fin;
  Acc drive;
  double bank_err = 0.0;
  std::size_t triad = 0;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const auto& s = samples[k];
    est.update(s.input);
    const VehicleEstimate& e = est.estimate();
    if (!e.valid) {
      continue;
    }
    const Eigen::Vector3d err(e.roll_rad - s.true_roll_rad, e.pitch_rad - s.true_pitch_rad,
                              wrap_angle(e.yaw_rad - s.true_yaw_rad));
    all.add_sq(err);
    if (std::abs(s.true_lateral_accel_mps2) > 1.0) {
      lat.add_sq(err);
    }
    if (k >= final_from) {
      fin.add_abs(err);
    }
    if (k >= drive_from && k < brake_idx) {
      drive.add_abs(err);
    }
    if (std::abs(s.road_bank_rad) > 15.0 * kRadPerDeg && s.true_speed_mps > 1.0) {
      bank_err += err(0);
      ++score.bank_samples;
    }
    triad += e.from_triad ? 1U : 0U;
  }
  score.samples = all.n;
  score.rmse = all.rms();
  score.rmse_lateral = lat.rms();
  score.lateral_samples = lat.n;
  score.final_abs_error = fin.mean();
  score.driving_end_abs_error = drive.mean();
  if (score.bank_samples > 0) {
    score.mean_roll_error_on_bank_deg = bank_err / static_cast<double>(score.bank_samples) * kDegPerRad;
  }
  score.triad_fraction = all.n > 0 ? static_cast<double>(triad) / static_cast<double>(all.n) : 0.0;
  score.rejects = est.rejects();
  return score;
}

VehicleBenchFigures bench_vehicle(int n, int repeats, const VehicleParams& params) {
  VehicleSimConfig sim;
  sim.scenario = "mountain_road";
  const auto samples = simulate_vehicle(sim);
  if (samples.empty()) {
    return {};
  }
  const std::size_t len = samples.size();
  const int64_t span_ns = samples.back().input.stamp_ns - samples.front().input.stamp_ns + 10'000'000;
  double sink = 0.0;
  const BenchFigures f = best_of_runs(n, repeats, [&] {
    auto est = std::make_shared<VehicleEstimator>(params);
    return [&, est](int i) {
      VehicleSample s = samples[static_cast<std::size_t>(i) % len].input;  // the drive, repeated in time
      s.stamp_ns += static_cast<int64_t>(static_cast<std::size_t>(i) / len) * span_ns;
      est->update(s);
      sink += est->estimate().roll_rad;
    };
  });
  volatile double keep = sink;
  (void)keep;
  return f;
}

}  // namespace poise
