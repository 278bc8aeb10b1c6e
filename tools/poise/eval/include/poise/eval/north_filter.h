// True north for a filter run by the evaluation tools (`poise eval broad`, `tune`, `bench
// filters`, `process --filter`): the same north keys as a host file's component params
// (poise/core/north_yaml.h), given as `--set KEY=VALUE`; the output turned into true ENU as the
// nodes turn theirs (NorthReference::to_true, frame id enu_true).
#pragma once

#include "poise/core/attitude_filter.h"
#include "poise/core/north.h"

#include <memory>
#include <string>
#include <vector>

namespace poise::eval {

/// North from `--set KEY=VALUE` assignments (VALUE read as YAML: `declination_deg=3.4`,
/// `location={lat_deg: 48.1, lon_deg: 11.6}`, `date=2026-11-24`), resolved on `today`
/// (YYYY-MM-DD). No assignment: magnetic ENU. Throws std::invalid_argument naming the assignment:
/// a key that is not a north key (filter parameters belong in the filter's YAML), a value that is
/// not YAML or of the wrong type, and every refusal of resolve_north(). `also_known`: keys the
/// caller takes out before (e.g. `poise process`'s node keys), listed in the unknown-key message.
NorthReference north_from_sets(const std::vector<std::string>& sets, const std::string& today,
                               const std::vector<std::string>& also_known = {});

/// `filter` with its q_world_body turned into true ENU when `north.true_north` (else `filter`
/// itself, unchanged). Trial inputs (eval::TrialInputs) are passed on.
std::unique_ptr<AttitudeFilter> with_north(std::unique_ptr<AttitudeFilter> filter, const NorthReference& north);

}  // namespace poise::eval
