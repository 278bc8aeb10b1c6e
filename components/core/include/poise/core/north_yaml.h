// The north keys every attitude filter run takes (host-file component params, `--set KEY=VALUE`
// of `poise eval broad`, `tune`, `bench filters`, `process --filter`, a component run alone):
//   declination_deg: D                            # deg east of true north; or
//   location: {lat_deg: .., lon_deg: .., alt_m: ..}  # WGS 84; D (and |B|, dip) from the model
//   date: YYYY-MM-DD | decimal year               # optional, with a location (default: today, UTC)
//   magnetic_model: FILE.COF                      # optional, with a location (default: WMM2025)
//   seed_field: true | false                      # optional, with a location
// Header-only (yaml-cpp), no clock: the caller resolves with resolve_north(p, today).
#pragma once

#include "poise/core/north.h"
#include "poise/core/yaml_params.h"

#include <yaml-cpp/yaml.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace poise {

/// The keys read_north_params() reads.
inline const std::vector<std::string>& north_param_keys() {
  static const std::vector<std::string> k{"declination_deg", "location", "date", "magnetic_model", "seed_field"};
  return k;
}

/// NorthParams from a map holding (some of) the north keys; other keys are ignored (the caller
/// checks its own). Throws std::invalid_argument saying what to fix: a location that is not
/// {lat_deg, lon_deg[, alt_m]} numbers, date / magnetic_model without a location, a value of the
/// wrong type. Both declination_deg and location given is refused by resolve_north().
inline NorthParams read_north_params(const YAML::Node& params) {
  NorthParams p;
  if (!params || !params.IsMap()) {
    return p;
  }
  auto get = [&params](const char* key, auto& out, const char* what) {
    const YAML::Node v = params[key];
    if (!v) {
      return;
    }
    if (v.IsNull()) {  // never silently "not configured"
      throw std::invalid_argument(std::string(key) + " has no value (empty or ~): give " + what +
                                  ", or leave the key out");
    }
    try {
      out = v.as<std::decay_t<decltype(out)>>();
    } catch (const YAML::Exception&) {
      throw std::invalid_argument(std::string(key) + " must be " + what);
    }
  };
  get("declination_deg", p.declination_deg, "a number (deg east of true north)");
  get("date", p.date, "a date (YYYY-MM-DD or a decimal year)");
  get("magnetic_model", p.model_file, "a file name (.COF)");
  get("seed_field", p.seed_field, "true or false");
  const YAML::Node loc = params["location"];
  if (loc && loc.IsNull()) {
    throw std::invalid_argument("location has no value (empty or ~): give {lat_deg, lon_deg, alt_m}, or leave the key out");
  }
  if (loc) {
    if (!loc.IsMap()) {
      throw std::invalid_argument("location must be a mapping {lat_deg, lon_deg, alt_m}");
    }
    check_known_keys<std::invalid_argument>(loc, {"lat_deg", "lon_deg", "alt_m"}, "north", "location.");
    if (!loc["lat_deg"] || !loc["lon_deg"]) {
      throw std::invalid_argument("location needs lat_deg and lon_deg (alt_m optional, default 0)");
    }
    try {
      p.location.lat_deg = loc["lat_deg"].as<double>();
      p.location.lon_deg = loc["lon_deg"].as<double>();
      p.location.alt_m = loc["alt_m"] ? loc["alt_m"].as<double>() : 0.0;
    } catch (const YAML::Exception&) {
      throw std::invalid_argument("location: lat_deg, lon_deg and alt_m must be numbers (deg, deg, m)");
    }
    p.has_location = true;
  } else if (!p.date.empty() || !p.model_file.empty()) {
    throw std::invalid_argument("date and magnetic_model need a location");
  }
  return p;
}

}  // namespace poise
