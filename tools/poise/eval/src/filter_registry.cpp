#include "poise/eval/filter_registry.h"

#include "poise/eval/broad.h"

#include "poise/gauss_newton/gauss_newton.h"
#include "poise/parallel_kf/parallel_kf.h"

#include <cstdio>
#include <stdexcept>

namespace poise::eval {
namespace {

std::vector<FilterEntry>& table() {
  static std::vector<FilterEntry> t = [] {
    std::vector<FilterEntry> v;
    v.push_back({"gauss_newton", "Gauss-Newton orientation from accel + mag (baseline, no disturbance handling)",
                 [](const std::string& cfg) -> std::unique_ptr<AttitudeFilter> {
                   return std::make_unique<GaussNewtonFilter>(cfg.empty() ? GaussNewtonParams{}
                                                                          : load_gauss_newton_params(cfg));
                 },
                 nullptr});
    v.push_back({"parallel_kf", "parallel Kalman filter, shipped default configuration (paper 000 + extensions)",
                 [](const std::string& cfg) -> std::unique_ptr<AttitudeFilter> {
                   return std::make_unique<ParallelKfFilter>(cfg.empty() ? ParallelKfParams::defaults()
                                                                         : load_parallel_kf_params(cfg));
                 },
                 // On BROAD without --config: the defaults with BROAD's IMU delay (the sensor's
                 // calibration), said once on stderr so that no figure hides it.
                 []() -> std::unique_ptr<AttitudeFilter> {
                   static bool said = false;
                   if (!said) {
                     said = true;
                     std::fprintf(stderr,
                                  "parallel KF: BROAD's IMU delay applied, imu_delay_s = %.5f s (measured on "
                                  "trials 01-18 with `poise calibrate imu-delay`); --config "
                                  "config/filters/parallel_kf.yaml runs without it\n",
                                  kBroadImuDelayS);
                   }
                   return std::make_unique<ParallelKfFilter>(broad_parallel_kf_params());
                 }});
    v.push_back({"parallel_kf_paper", "parallel Kalman filter, paper-faithful configuration (eqs. 1-11)",
                 [](const std::string& cfg) -> std::unique_ptr<AttitudeFilter> {
                   return std::make_unique<ParallelKfFilter>(
                       cfg.empty() ? ParallelKfParams::paper()
                                   : load_parallel_kf_params(cfg, ParallelKfParams::paper()));
                 },
                 nullptr});
    return v;
  }();
  return t;
}

}  // namespace

ParallelKfParams broad_parallel_kf_params() {
  ParallelKfParams p = ParallelKfParams::defaults();
  p.imu_delay_s = kBroadImuDelayS;
  return p;
}

void register_filter(const std::string& name, const std::string& description, FilterFactory factory,
                     std::function<std::unique_ptr<AttitudeFilter>()> broad_default) {
  for (auto& e : table()) {
    if (e.name == name) {
      e.description = description;
      e.factory = std::move(factory);
      e.broad_default = std::move(broad_default);
      return;
    }
  }
  table().push_back({name, description, std::move(factory), std::move(broad_default)});
}

std::vector<FilterEntry> registered_filters() { return table(); }

std::unique_ptr<AttitudeFilter> make_filter(const std::string& name, const std::string& config_path) {
  for (const auto& e : table()) {
    if (e.name == name) {
      return e.factory(config_path);
    }
  }
  return make_filter_for_broad(name, config_path);  // unknown: the same error
}

std::unique_ptr<AttitudeFilter> make_filter_for_broad(const std::string& name, const std::string& config_path) {
  for (const auto& e : table()) {
    if (e.name == name) {
      return config_path.empty() && e.broad_default ? e.broad_default() : e.factory(config_path);
    }
  }
  std::string known;
  for (const auto& e : table()) {
    known += (known.empty() ? "" : ", ") + e.name;
  }
  throw std::invalid_argument("unknown filter '" + name + "' (known: " + known + ")");
}

}  // namespace poise::eval
