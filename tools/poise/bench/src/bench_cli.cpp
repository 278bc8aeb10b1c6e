// `poise bench latency|record|replay`. The other benchmarks register beside the code they time:
// `bench filters|altitude|vehicle` (tools/poise/eval), `bench camera|imu` (tools/poise/sensors),
// `bench cdr` (tools/poise/topics); all of them time with poise/bench/bench.h.
#include <CLI/CLI.hpp>

namespace poise::cli {

void register_bench_latency(CLI::App& app);
void register_bench_record(CLI::App& app);

void register_bench_commands(CLI::App& app) {
  register_bench_latency(app);
  register_bench_record(app);
}

}  // namespace poise::cli
