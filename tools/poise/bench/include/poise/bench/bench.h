// Timing for the `poise bench ...` commands. Its own library (poise_bench), outside the cores:
// cores never read clocks (tools/check_cores.sh checks it).
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <ctime>

namespace poise {

/// CPU time of the calling thread, ns: immune to other processes competing for the cores.
inline int64_t thread_cpu_ns() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

/// Cost of one update, ns per sample: thread CPU time (what the code costs) and wall time
/// (inflated when other processes share the cores).
struct BenchFigures {
  double cpu_ns_per_sample = 0.0;
  double wall_ns_per_sample = 0.0;
};

/// Best of `repeats` runs of `n` steps. `make_run()` is called before each run (fresh state, not
/// timed) and returns the step, called as step(i) for i in [0, n).
template <class MakeRun>
BenchFigures best_of_runs(int n, int repeats, MakeRun make_run) {
  if (n <= 0) {
    return {};
  }
  BenchFigures best{1e300, 1e300};
  for (int r = 0; r < std::max(1, repeats); ++r) {
    auto step = make_run();
    const int64_t c0 = thread_cpu_ns();
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) {
      step(i);
    }
    const auto t1 = std::chrono::steady_clock::now();
    const int64_t c1 = thread_cpu_ns();
    const auto dn = static_cast<double>(n);
    best.cpu_ns_per_sample = std::min(best.cpu_ns_per_sample, static_cast<double>(c1 - c0) / dn);
    best.wall_ns_per_sample = std::min(
        best.wall_ns_per_sample,
        static_cast<double>(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()) / dn);
  }
  return best;
}

}  // namespace poise
