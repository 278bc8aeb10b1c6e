// The table of attitude filters known to `poise eval broad` and `poise bench filters`.
// Built in: gauss_newton, parallel_kf (default configuration), parallel_kf_paper. Another library
// adds its filter by calling register_filter() from its CLI module function (it runs before any
// command is parsed), e.g. the selective EKF as "selective".
#pragma once

#include "poise/core/attitude_filter.h"
#include "poise/parallel_kf/parallel_kf.h"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace poise::eval {

/// Creates a filter; `config_path` is empty for the built-in defaults, else a YAML file.
using FilterFactory = std::function<std::unique_ptr<AttitudeFilter>(const std::string& config_path)>;

struct FilterEntry {
  std::string name;
  std::string description;
  FilterFactory factory;
  /// Optional: the filter for BROAD's sensor when no config is given (e.g. with BROAD's measured
  /// IMU delay). Used by `poise eval broad` and `poise bench filters` only; null = factory("").
  std::function<std::unique_ptr<AttitudeFilter>()> broad_default;
};

/// Adds (or replaces) a named filter.
void register_filter(const std::string& name, const std::string& description, FilterFactory factory,
                     std::function<std::unique_ptr<AttitudeFilter>()> broad_default = nullptr);
/// All registered filters, in registration order (built-ins first).
std::vector<FilterEntry> registered_filters();
/// Creates filter `name`; throws std::invalid_argument listing the known names.
std::unique_ptr<AttitudeFilter> make_filter(const std::string& name, const std::string& config_path = "");
/// As make_filter, but for BROAD data: without a config, the entry's broad_default when it has one.
std::unique_ptr<AttitudeFilter> make_filter_for_broad(const std::string& name, const std::string& config_path = "");

/// The parallel KF's defaults with BROAD's IMU delay: what `poise eval broad` runs without --config
/// (config/filters/parallel_kf_broad.yaml holds the same).
ParallelKfParams broad_parallel_kf_params();

}  // namespace poise::eval
