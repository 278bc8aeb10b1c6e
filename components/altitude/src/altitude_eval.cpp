#include "poise/altitude/altitude_eval.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>

namespace poise {
namespace {

int64_t thread_cpu_ns() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

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
  AltitudeBenchFigures best{1e300, 1e300};
  if (samples.empty() || n <= 0) {
    return {};
  }
  const std::size_t len = samples.size();
  const int64_t span_ns = samples.back().imu.stamp_ns - samples.front().imu.stamp_ns + 10'000'000;
  double sink = 0.0;
  for (int r = 0; r < std::max(1, repeats); ++r) {
    AltitudeFilter filter(params);
    const int64_t c0 = thread_cpu_ns();
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) {
      const auto idx = static_cast<std::size_t>(i) % len;
      ImuSample s = samples[idx].imu;
      s.stamp_ns += static_cast<int64_t>(static_cast<std::size_t>(i) / len) * span_ns;
      filter.update(s);
      sink += filter.estimate().vertical_velocity_mps;
    }
    const auto t1 = std::chrono::steady_clock::now();
    const int64_t c1 = thread_cpu_ns();
    const auto dn = static_cast<double>(n);
    best.cpu_ns_per_sample = std::min(best.cpu_ns_per_sample, static_cast<double>(c1 - c0) / dn);
    best.wall_ns_per_sample = std::min(
        best.wall_ns_per_sample,
        static_cast<double>(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()) / dn);
  }
  volatile double keep = sink;
  (void)keep;
  return best;
}

}  // namespace poise
