// The command shape of the per-sample benchmarks of one estimator with variants
// (`poise bench altitude --method M`, `poise bench vehicle --mode M`): best of 3 runs.
#pragma once

#include "poise/bench/bench.h"
#include "poise/cli/common.h"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace poise::cli {

/// Registers `poise bench NAME [--samples N] [OPTION V]`; prints
/// "NAME V: X ns/sample cpu, Y ns/sample wall (best of 3 x N samples)".
inline void add_variant_bench(CLI::App& app, const std::string& name, const std::string& description,
                              const std::string& option, const std::string& option_help,
                              const std::vector<std::string>& variants, const std::string& default_variant,
                              std::function<BenchFigures(int samples, int repeats, const std::string& variant)> run) {
  constexpr int kRepeats = 3;
  CLI::App* group = subcommand_group(app, "bench", "Benchmarks (figures printed, not asserted)");
  CLI::App* bench = group->add_subcommand(name, description);
  auto samples = std::make_shared<int>(200000);
  auto variant = std::make_shared<std::string>(default_variant);
  bench->add_option("--samples", *samples, "Samples per run (best of 3 runs)")
      ->check(CLI::Range(1, 100000000))
      ->capture_default_str();
  bench->add_option(option, *variant, option_help)->check(CLI::IsMember(variants))->capture_default_str();
  bench->callback([name, samples, variant, run = std::move(run)]() {
    const BenchFigures f = run(*samples, kRepeats, *variant);
    std::printf("%s %s: %.0f ns/sample cpu, %.0f ns/sample wall (best of %d x %d samples)\n", name.c_str(),
                variant->c_str(), f.cpu_ns_per_sample, f.wall_ns_per_sample, kRepeats, *samples);
  });
}

}  // namespace poise::cli
