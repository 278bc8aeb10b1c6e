// `poise sim altitude`: simulate a paper-003 test profile, run the altitude filter, print RMSE.
#include "poise/eval/altitude_eval.h"
#include "poise/bench/bench_cli.h"
#include "poise/cli/common.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

namespace poise::cli {
namespace {

std::string score_json(const AltitudeScore& s, const AltitudeParams& p) {
  const nlohmann::ordered_json j = {{"profile", s.profile},
                                    {"method", s.method},
                                    {"gains", to_string(p.gains)},
                                    {"seed", s.seed},
                                    {"samples", s.samples},
                                    {"height_rmse_m", s.height_rmse_m},
                                    {"vertical_velocity_rmse_mps", s.velocity_rmse_mps},
                                    {"baro_height_rmse_m", s.baro_height_rmse_m},
                                    {"max_abs_velocity_error_mps", s.max_abs_velocity_error_mps},
                                    {"stationary_fraction", s.stationary_fraction},
                                    {"true_stationary_fraction", s.stationary_true_fraction},
                                    {"rejected", s.rejects.total()}};
  return j.dump();  // NaN / infinity -> null: valid JSON
}

}  // namespace

// not split: the options and help of `sim altitude` and `bench altitude` in the order --help
// prints them.
void register_altitude_cli(CLI::App& app) {
  add_variant_bench(app, "altitude", "Cost of the altitude filter (tilt KF included) per sample, on the simulated test 1",
                    "--method", "Method to time", {"two_step_kf", "cf_zupt", "pi_cf_zupt", "pi_cf"}, "pi_cf_zupt",
                    [](int samples, int repeats, const std::string& method) {
                      AltitudeParams p;
                      parse_altitude_method(method, p.method);
                      return bench_altitude(samples, repeats, p);
                    });

  CLI::App* sim_group = subcommand_group(app, "sim", "Simulators: run an estimator on synthetic data");
  CLI::App* cmd = sim_group->add_subcommand(
      "altitude",
      "Altitude / vertical-velocity filter (paper 003) on a simulated GY-87 test profile: prints "
      "height and vertical-velocity RMSE");
  struct Options {
    std::string profile = "random";
    std::string method = "pi_cf_zupt";
    std::string gains;
    std::string config;
    uint64_t seed = 1;
    bool json = false;
    bool compare = false;
  };
  auto opt = std::make_shared<Options>();
  std::string profiles_help = "Test profile of paper 003:";
  for (const auto& name : altitude_sim_profiles()) {
    profiles_help += " " + name;
  }
  cmd->add_option("--scenario", opt->profile, profiles_help)
      ->check(CLI::IsMember(altitude_sim_profiles()))
      ->capture_default_str();
  add_deprecated_alias(cmd, "--profile", "--scenario", &opt->profile)->check(CLI::IsMember(altitude_sim_profiles()));
  cmd->add_option("--method", opt->method,
                  "two_step_kf (method 1), cf_zupt (2), pi_cf_zupt (3, paper), pi_cf (3 without ZUPT)")
      ->check(CLI::IsMember({"two_step_kf", "cf_zupt", "pi_cf_zupt", "pi_cf"}))
      ->capture_default_str();
  cmd->add_option("--gains", opt->gains,
                  "CF gains: paper (printed eq. 14) or higgins (steady-state KF); default from config")
      ->check(CLI::IsMember({"paper", "higgins"}));
  cmd->add_option("--config", opt->config, "Altitude filter YAML (default: built-in defaults)");
  cmd->add_option("--seed", opt->seed, "Simulator seed")->capture_default_str();
  cmd->add_flag("--json", opt->json, "Print one JSON object");
  cmd->add_flag("--compare", opt->compare,
                "Run every profile with methods 1, 2, 3 and 3-without-ZUPT and print a table");
  cmd->callback([opt]() {
    AltitudeParams params;
    if (!opt->config.empty()) {
      try {
        params = load_altitude_params(opt->config);
      } catch (const std::exception& e) {
        throw Error(std::string(e.what()) + " (fix the file or omit --config)");
      }
    }
    if (!opt->gains.empty()) {
      parse_cf_gains(opt->gains, params.gains);
    }
    if (opt->compare) {
      const std::vector<AltitudeMethod> methods = {AltitudeMethod::kTwoStepKf, AltitudeMethod::kCfZupt,
                                                   AltitudeMethod::kPiCfZupt, AltitudeMethod::kPiCf};
      if (!opt->json) {
        std::printf("vertical-velocity RMSE m/s (height RMSE m), seed %llu, gains %s\n",
                    static_cast<unsigned long long>(opt->seed), to_string(params.gains));
        std::printf("%-18s", "profile");
        for (auto m : methods) {
          std::printf(" %-20s", to_string(m));
        }
        std::printf("\n");
      } else {
        std::printf("[");
      }
      bool first = true;
      for (const auto& profile : altitude_sim_profiles()) {
        if (!opt->json) {
          std::printf("%-18s", profile.c_str());
        }
        for (auto m : methods) {
          AltitudeSimConfig sim_config;
          sim_config.profile = profile;
          sim_config.seed = opt->seed;
          params.method = m;
          const AltitudeScore s = score_altitude(sim_config, params);
          if (opt->json) {
            std::printf("%s%s", first ? "" : ",", score_json(s, params).c_str());
            first = false;
          } else {
            std::printf(" %6.4f (%6.3f)      ", s.velocity_rmse_mps, s.height_rmse_m);
          }
        }
        if (!opt->json) {
          std::printf("\n");
        }
        std::fflush(stdout);
      }
      if (opt->json) {
        std::printf("]\n");
      }
      return;
    }
    parse_altitude_method(opt->method, params.method);
    AltitudeSimConfig sim_config;
    sim_config.profile = opt->profile;
    sim_config.seed = opt->seed;
    const AltitudeScore s = score_altitude(sim_config, params);
    if (opt->json) {
      std::cout << score_json(s, params) << "\n";
      return;
    }
    std::printf("profile %s, method %s, gains %s, seed %llu, %zu samples\n", s.profile.c_str(),
                s.method.c_str(), to_string(params.gains), static_cast<unsigned long long>(s.seed),
                s.samples);
    std::printf("  vertical velocity RMSE  %.4f m/s (max |error| %.3f m/s)\n", s.velocity_rmse_mps,
                s.max_abs_velocity_error_mps);
    std::printf("  height RMSE             %.4f m (raw baro %.4f m)\n", s.height_rmse_m,
                s.baro_height_rmse_m);
    std::printf("  stationary flagged      %.1f %% of samples (truly still %.1f %%)\n",
                100.0 * s.stationary_fraction, 100.0 * s.stationary_true_fraction);
    std::printf("  rejected samples        %llu\n",
                static_cast<unsigned long long>(s.rejects.total()));
  });
}

}  // namespace poise::cli
