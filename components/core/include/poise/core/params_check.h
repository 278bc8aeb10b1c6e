// One shape of parameter validation for every estimator core: `validate()` throws
// std::invalid_argument naming the filter, the key (as spelled in its YAML file) and the accepted
// range with its unit, e.g. "altitude parameter cf.sigma_baro_m must be finite and > 0 (m), got 0".
// Loaders catch it and prefix the file name; nodes and tools report it as a startup error.
#pragma once

#include "poise/core/sample_check.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace poise {

class ParamCheck {
 public:
  /// `filter`: the name in messages (the YAML section, e.g. "parallel_kf").
  explicit ParamCheck(const char* filter) : filter_(filter) {}

  /// Throws "<filter> parameter <key> must be <what>" when !ok. `what` states the range and unit,
  /// e.g. "in [0, 1)" or "> 0 (rad/s)".
  void require(bool ok, const char* key, const char* what) const {
    if (!ok) {
      throw std::invalid_argument(std::string(filter_) + " parameter " + key + " must be " + what);
    }
  }
  /// Finite and > 0; `unit` as written in the key's documentation (e.g. "m/s^2").
  void positive(double v, const char* key, const char* unit) const {
    check_value(std::isfinite(v) && v > 0.0, v, key, "finite and > 0", unit);
  }
  /// Finite and >= 0.
  void non_negative(double v, const char* key, const char* unit) const {
    check_value(std::isfinite(v) && v >= 0.0, v, key, "finite and >= 0", unit);
  }

 private:
  void check_value(bool ok, double v, const char* key, const char* range, const char* unit) const {
    if (!ok) {
      std::ostringstream m;
      m << filter_ << " parameter " << key << " must be " << range << " (" << unit << "), got " << v;
      throw std::invalid_argument(m.str());
    }
  }
  const char* filter_;
};

/// Validates sample limits under the keys limits.* (every core with a SampleLimits uses this).
inline void validate(const SampleLimits& l, const ParamCheck& check) {
  check.positive(l.min_accel_norm_mps2, "limits.min_accel_norm_mps2", "m/s^2");
  check.positive(l.min_mag_norm_ut, "limits.min_mag_norm_ut", "uT");
  check.positive(l.max_dt_s, "limits.max_dt_s", "s");
  check.positive(l.max_gyro_rps, "limits.max_gyro_rps", "rad/s");
  check.positive(l.max_accel_mps2, "limits.max_accel_mps2", "m/s^2");
  check.positive(l.max_mag_ut, "limits.max_mag_ut", "uT");
}

/// For loaders: runs `validate()` on parameters read from `path` and rethrows its
/// std::invalid_argument as std::runtime_error prefixed with the file name.
template <class Params>
void validate_loaded(const Params& p, const std::string& path) {
  try {
    p.validate();
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

}  // namespace poise
