#include "poise/eval/altitude_eval.h"

#include "poise/bench/bench.h"

#include <algorithm>
#include <cmath>
#include <memory>

namespace poise {

AltitudeScore score_altitude(const AltitudeSimConfig& sim, const AltitudeParams& params) {
  const auto samples = simulate_altitude(sim);
  AltitudeFilter filter(params);
  AltitudeScore score;
  score.profile = sim.profile;
  score.method = to_string(params.method);
  score.seed = sim.seed;
  double se_h = 0.0;
  double se_v = 0.0;
  double se_b = 0.0;
  std::size_t n = 0;
  std::size_t n_stat = 0;
  std::size_t n_true_stat = 0;
  for (const auto& s : samples) {
    filter.update(s.imu);
    const AltitudeEstimate& e = filter.estimate();
    if (!e.valid) {
      continue;
    }
    const double eh = e.height_m - s.true_height_m;
    const double ev = e.vertical_velocity_mps - s.true_vertical_velocity_mps;
    const double eb = e.baro_height_m - s.true_height_m;
    se_h += eh * eh;
    se_v += ev * ev;
    se_b += eb * eb;
    score.max_abs_velocity_error_mps = std::max(score.max_abs_velocity_error_mps, std::abs(ev));
    n_stat += e.stationary ? 1U : 0U;
    n_true_stat += s.true_stationary ? 1U : 0U;
    ++n;
  }
  score.samples = n;
  if (n > 0) {
    const auto dn = static_cast<double>(n);
    score.height_rmse_m = std::sqrt(se_h / dn);
    score.velocity_rmse_mps = std::sqrt(se_v / dn);
    score.baro_height_rmse_m = std::sqrt(se_b / dn);
    score.stationary_fraction = static_cast<double>(n_stat) / dn;
    score.stationary_true_fraction = static_cast<double>(n_true_stat) / dn;
  }
  score.rejects = filter.rejects();
  return score;
}

AltitudeBenchFigures bench_altitude(int n, int repeats, const AltitudeParams& params) {
  AltitudeSimConfig sim;
  sim.profile = "random";
  const auto samples = simulate_altitude(sim);
  if (samples.empty()) {
    return {};
  }
  const std::size_t len = samples.size();
  const int64_t span_ns = samples.back().imu.stamp_ns - samples.front().imu.stamp_ns + 10'000'000;
  double sink = 0.0;
  const BenchFigures f = best_of_runs(n, repeats, [&] {
    auto filter = std::make_shared<AltitudeFilter>(params);
    return [&, filter](int i) {
      ImuSample s = samples[static_cast<std::size_t>(i) % len].imu;  // the profile, repeated in time
      s.stamp_ns += static_cast<int64_t>(static_cast<std::size_t>(i) / len) * span_ns;
      filter->update(s);
      sink += filter->estimate().vertical_velocity_mps;
    };
  });
  volatile double keep = sink;
  (void)keep;
  return f;
}

}  // namespace poise
