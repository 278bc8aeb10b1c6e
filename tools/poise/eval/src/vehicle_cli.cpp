// `poise sim vehicle`: simulate a paper-001 case, run TRIAD alone, EKF alone and the switched
// estimator, print roll/pitch/yaw RMSE.
#include "poise/bench/bench_cli.h"
#include "poise/cli/common.h"
#include "poise/eval/vehicle_eval.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace poise::cli {
namespace {

nlohmann::ordered_json rpy_json(const Rpy& r) {
  return {{"roll_deg", r.roll_deg}, {"pitch_deg", r.pitch_deg}, {"yaw_deg", r.yaw_deg}};
}

// NaN / infinity (e.g. no banked sample: mean over none) -> null: valid JSON.
nlohmann::ordered_json score_json(const VehicleScore& s) {
  return {{"rmse", rpy_json(s.rmse)},
          {"rmse_lateral", rpy_json(s.rmse_lateral)},
          {"lateral_samples", s.lateral_samples},
          {"driving_end_abs_error", rpy_json(s.driving_end_abs_error)},
          {"final_abs_error", rpy_json(s.final_abs_error)},
          {"mean_roll_error_on_bank_deg", s.mean_roll_error_on_bank_deg},
          {"bank_samples", s.bank_samples},
          {"triad_fraction", s.triad_fraction},
          {"samples", s.samples},
          {"rejected", s.rejects.total()}};
}

void print_row(const char* label, const Rpy& r) {
  std::printf("  %-26s %8.3f %8.3f %8.3f\n", label, r.roll_deg, r.pitch_deg, r.yaw_deg);
}

}  // namespace

void register_vehicle_cli(CLI::App& app) {
  add_variant_bench(app, "vehicle", "Cost of the vehicle estimator per sample, on the simulated mountain road",
                    "--mode", "switched, triad or ekf", {"switched", "triad", "ekf"}, "switched",
                    [](int samples, int repeats, const std::string& mode) {
                      VehicleParams p;
                      parse_vehicle_mode(mode, p.mode);
                      return bench_vehicle(samples, repeats, p);
                    });

  CLI::App* sim_group = subcommand_group(app, "sim", "Simulators: run an estimator on synthetic data");
  CLI::App* cmd = sim_group->add_subcommand(
      "vehicle",
      "Vehicle attitude (paper 001) on a simulated case: roll/pitch/yaw RMSE of TRIAD alone, EKF "
      "alone and the switched estimator");
  struct Options {
    std::string scenario = "double_lane_change";
    std::string config;
    uint64_t seed = 1;
    bool json = false;
  };
  auto opt = std::make_shared<Options>();
  std::string help = "Case of paper 001 Table 1:";
  for (const auto& n : vehicle_sim_scenarios()) {
    help += " " + n;
  }
  cmd->add_option("--case", opt->scenario, help)
      ->check(CLI::IsMember(vehicle_sim_scenarios()))
      ->capture_default_str();
  cmd->add_option("--config", opt->config, "Vehicle estimator YAML (default: built-in defaults)");
  cmd->add_option("--seed", opt->seed, "Simulator seed")->capture_default_str();
  cmd->add_flag("--json", opt->json, "Print one JSON object");
  cmd->callback([opt]() {
    VehicleParams params;
    if (!opt->config.empty()) {
      try {
        params = load_vehicle_params(opt->config);
      } catch (const std::exception& e) {
        throw Error(std::string(e.what()) + " (fix the file or omit --config)");
      }
    }
    VehicleSimConfig sim;
    sim.scenario = opt->scenario;
    sim.seed = opt->seed;
    std::vector<VehicleScore> scores;
    for (VehicleMode m : {VehicleMode::kTriad, VehicleMode::kEkf, VehicleMode::kSwitched}) {
      params.mode = m;
      scores.push_back(score_vehicle(sim, params));
    }
    if (opt->json) {
      nlohmann::ordered_json j = {{"case", sim.scenario}, {"seed", sim.seed}};
      for (const auto& s : scores) {
        j[s.mode] = score_json(s);
      }
      std::printf("%s\n", j.dump().c_str());
      return;
    }
    std::printf("case %s, seed %llu, %zu samples at %.0f Hz (errors in deg: roll pitch yaw)\n",
                sim.scenario.c_str(), static_cast<unsigned long long>(sim.seed), scores[0].samples,
                sim.rate_hz);
    for (const auto& s : scores) {
      std::printf("%s%s\n", s.mode.c_str(),
                  s.mode == "switched" ? " (TRIAD when static, EKF when driving)" : "");
      print_row("RMSE, whole run", s.rmse);
      if (s.lateral_samples > 0) {
        print_row("RMSE, lateral manoeuvres", s.rmse_lateral);
      }
      print_row("mean |err|, end of driving", s.driving_end_abs_error);
      print_row("mean |err|, final stop", s.final_abs_error);
      if (s.bank_samples > 0) {
        std::printf("  %-26s %8.3f\n", "mean roll err on the bank", s.mean_roll_error_on_bank_deg);
      }
    }
  });
}

}  // namespace poise::cli
