// Parameter choice that cannot flatter itself: a grid of candidate values for named filter
// parameters, evaluated on every trial, chosen on some trials and scored on the others
// (K-fold, default leave one trial out). Pure functions; the CLI (`poise eval broad --grid`,
// `poise tune`) runs the filters.
#pragma once

#include "poise/eval/runner.h"

#include <string>
#include <utility>
#include <vector>

namespace poise::eval {

/// One parameter and the values to try: "key=v1,v2,..." (key as in the filter's YAML, dotted
/// for nested fields, e.g. tilt.sigma_accel_mps2; values as YAML scalars).
struct GridAxis {
  std::string key;
  std::vector<std::string> values;
};
using Overrides = std::vector<std::pair<std::string, std::string>>;

/// Parses "key=v1,v2". Throws std::invalid_argument naming the spec when the key or a value is
/// empty, a key repeats, or the whole grid exceeds `max_points` candidates.
std::vector<GridAxis> parse_grid(const std::vector<std::string>& specs, size_t max_points = 4096);
/// Every combination, first axis slowest. An empty grid gives one empty candidate.
std::vector<Overrides> grid_points(const std::vector<GridAxis>& axes);
/// "key=v key2=v2".
std::string describe(const Overrides& o);

/// Writes `base_yaml_path` (or an empty map when empty) with the overrides set, to `out_path`.
/// Overrides go under the file's single top-level section when it has one (e.g. `parallel_kf:`),
/// else at the top level; dotted keys become nested maps. Throws std::runtime_error on I/O or
/// YAML errors, naming the file.
void write_config_with_overrides(const std::string& base_yaml_path, const Overrides& overrides,
                                 const std::string& out_path, const std::string& header_comment = "");

/// The figure a choice minimises: the mean of the undisturbed and the disturbed groups' mean total
/// RMSE (one group's mean when the other is empty), so both kinds of trial weigh the same.
double choice_objective(const std::vector<TrialResult>& results);

struct CrossValidation {
  int folds = 0;
  size_t in_sample_choice = 0;                ///< candidate best on all trials
  std::vector<TrialResult> in_sample;         ///< its per-trial results (in-sample figure)
  std::vector<TrialResult> cross_validated;   ///< each trial scored with the choice made without its fold
  std::vector<size_t> choice_per_trial;       ///< candidate chosen for each trial's fold
};

/// `by_candidate[c][t]`: trial t's result with candidate c (same trial order for every c).
/// Trial t belongs to fold t % folds; folds in [2, number of trials] (0 = leave one out).
/// Ties go to the lower candidate index. Throws std::invalid_argument on empty or ragged input.
CrossValidation cross_validate(const std::vector<std::vector<TrialResult>>& by_candidate, int folds);

}  // namespace poise::eval
