// Input validation shared by the estimator cores: bad data is rejected and counted by reason,
// never propagated into a state (STYLE.md habit 10).
#pragma once

#include "poise/core/types.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <string>

namespace poise {

enum class RejectReason : uint8_t {
  kNonFiniteGyro = 0,
  kNonFiniteAccel,
  kNonFiniteMag,
  kZeroAccel,        ///< |accel| below the minimum norm
  kZeroMag,          ///< |mag| below the minimum norm
  kNonMonotonicStamp,
  kTimeGap,          ///< dt above the maximum (the filter re-anchors time, state kept)
  kMissingGyro,
  kMissingAccel,
  kGyroOutOfRange,   ///< |gyro| above the sensor's full scale (finite but impossible, e.g. 1e308)
  kAccelOutOfRange,  ///< |accel| above the sensor's full scale
  kMagOutOfRange,    ///< |mag| above the sensor's full scale
  kStampOutOfRange,  ///< stamp < 0 or beyond kMaxStampNs (no sensor clock reads that)
  kNonFinitePressure,
  kPressureOutOfRange,  ///< static pressure outside the barometer's plausible range
  kNoMagnetometer,   ///< use_magnetometer: true, and the sample carries no magnetometer
  kCount
};

inline const char* to_string(RejectReason r) {
  switch (r) {
    case RejectReason::kNonFiniteGyro: return "non_finite_gyro";
    case RejectReason::kNonFiniteAccel: return "non_finite_accel";
    case RejectReason::kNonFiniteMag: return "non_finite_mag";
    case RejectReason::kZeroAccel: return "zero_accel";
    case RejectReason::kZeroMag: return "zero_mag";
    case RejectReason::kNonMonotonicStamp: return "non_monotonic_stamp";
    case RejectReason::kStampOutOfRange: return "stamp_out_of_range";
    case RejectReason::kTimeGap: return "time_gap";
    case RejectReason::kMissingGyro: return "missing_gyro";
    case RejectReason::kMissingAccel: return "missing_accel";
    case RejectReason::kGyroOutOfRange: return "gyro_out_of_range";
    case RejectReason::kAccelOutOfRange: return "accel_out_of_range";
    case RejectReason::kMagOutOfRange: return "mag_out_of_range";
    case RejectReason::kNonFinitePressure: return "non_finite_pressure";
    case RejectReason::kPressureOutOfRange: return "pressure_out_of_range";
    case RejectReason::kNoMagnetometer: return "no_magnetometer";
    case RejectReason::kCount: break;
  }
  return "unknown";
}

/// Counters per reason.
struct RejectCounters {
  std::array<uint64_t, static_cast<size_t>(RejectReason::kCount)> by_reason{};
  void add(RejectReason r) { ++by_reason[static_cast<size_t>(r)]; }
  [[nodiscard]] uint64_t count(RejectReason r) const { return by_reason[static_cast<size_t>(r)]; }
  [[nodiscard]] uint64_t total() const {
    uint64_t t = 0;
    for (auto c : by_reason) {
      t += c;
    }
    return t;
  }
  [[nodiscard]] std::map<std::string, uint64_t> to_map() const {
    std::map<std::string, uint64_t> m;
    for (size_t i = 0; i < by_reason.size(); ++i) {
      if (by_reason[i] != 0) {
        m[to_string(static_cast<RejectReason>(i))] = by_reason[i];
      }
    }
    return m;
  }
};

/// Whether an attitude filter uses the magnetometer (`use_magnetometer` in every attitude
/// filter's configuration):
///   kAuto      (`auto`, the default) when the sample carries one (ImuSample::has_mag);
///   kRequired  (`true`) every sample must carry one: a sample without is refused whole, counted
///              as no_magnetometer and reported rejected for every source, never used silently;
///   kOff       (`false`) never: 6-axis even when the sample carries one (its magnetometer is
///              neither checked nor counted; reported not available, "use_magnetometer_false").
enum class MagnetometerUse : uint8_t { kAuto = 0, kRequired, kOff };

/// The configuration spelling: "auto", "true", "false".
inline const char* to_string(MagnetometerUse u) {
  switch (u) {
    case MagnetometerUse::kAuto: return "auto";
    case MagnetometerUse::kRequired: return "true";
    case MagnetometerUse::kOff: return "false";
  }
  return "auto";
}

/// Parses "auto", "true" or "false" (exactly); false for anything else.
inline bool parse_magnetometer_use(const std::string& text, MagnetometerUse& out) {
  if (text == "auto") {
    out = MagnetometerUse::kAuto;
  } else if (text == "true") {
    out = MagnetometerUse::kRequired;
  } else if (text == "false") {
    out = MagnetometerUse::kOff;
  } else {
    return false;
  }
  return true;
}

/// Limits for check_imu_sample().
struct SampleLimits {
  double min_accel_norm_mps2 = 0.5;  ///< below: "zero" accelerometer (free fall is not usable)
  double min_mag_norm_ut = 1.0;      ///< below: "zero" magnetometer
  double max_dt_s = 0.5;             ///< larger gaps re-anchor time instead of integrating
  /// Physical range: a finite value beyond the sensor's full scale cannot be a measurement (one
  /// such sample would otherwise enter every state). Defaults: the MPU6050's and HMC5883L's
  /// largest ranges (2000 deg/s, 16 g, 8.1 G) with 25 % margin for calibration scale factors.
  double max_gyro_rps = 1.25 * 2000.0 * 3.14159265358979323846 / 180.0;
  double max_accel_mps2 = 1.25 * 16.0 * 9.80665;
  double max_mag_ut = 1.25 * 810.0;
};

/// Result of validating one sample against the previous accepted stamp.
struct SampleCheck {
  bool accept = false;      ///< gyro + accel usable and dt valid
  bool mag_ok = false;      ///< magnetometer usable (only meaningful when accept)
  bool reanchor = false;    ///< time gap: restart time from this stamp, do not integrate
  double dt_s = 0.0;        ///< > 0 when accept and not the first sample
  /// Why the sample was refused (kCount: accepted), and why its magnetometer was (kCount: usable
  /// or absent); the reasons the cores report per source.
  RejectReason reject = RejectReason::kCount;
  RejectReason mag_reject = RejectReason::kCount;
  /// Why no magnetometer was checked (mag_reject kCount and !mag_ok): none in the sample
  /// ("no_sample") or switched off by use_magnetometer: false ("use_magnetometer_false").
  const char* mag_absent = "no_sample";
};

/// One stamp against the previous accepted one: the time check every estimator core shares.
struct TimeStep {
  enum Kind : uint8_t { kFirst, kOk, kNonMonotonic, kGap } kind = kFirst;
  double dt_s = 0.0;  ///< stamp - previous, s (kOk and kGap)
};
/// `last_stamp_ns` < 0: no previous sample (kFirst). A stamp not after the previous one is
/// kNonMonotonic (reject it); dt above `max_dt_s` is kGap (restart time here, do not integrate).
inline TimeStep time_step(int64_t stamp_ns, int64_t last_stamp_ns, double max_dt_s) {
  TimeStep t;
  if (last_stamp_ns < 0) {
    return t;
  }
  if (stamp_ns <= last_stamp_ns) {
    t.kind = TimeStep::kNonMonotonic;
    return t;
  }
  t.dt_s = static_cast<double>(stamp_ns - last_stamp_ns) * 1e-9;
  t.kind = t.dt_s > max_dt_s ? TimeStep::kGap : TimeStep::kOk;
  return t;
}

/// The largest stamp a sensor clock can plausibly give: 2^62 ns, 146 years after its zero. Stamps
/// are ns of the sensor's clock (>= 0); beyond this, differences of two stamps could overflow.
constexpr int64_t kMaxStampNs = int64_t{1} << 62;

/// Why the gyro or accelerometer values of `s` are unusable, in the order check_imu_sample tests
/// them (non-finite gyro, non-finite accel, gyro out of range, accel out of range, zero accel);
/// kCount when usable. Out of line (sample_check.cpp): the usual sample does not need it.
RejectReason imu_values_reject(const ImuSample& s, const SampleLimits& lim);
/// Why the magnetometer reading is unusable (non-finite, zero, out of range), kCount when usable
/// (sample_check.cpp).
RejectReason mag_value_reject(const Eigen::Vector3d& mag_ut, const SampleLimits& lim);

/// Validates `s`; counts every problem found in `counters`. `last_stamp_ns` < 0 means "no
/// previous sample". Non-monotonic stamps are rejected; a gap above max_dt_s is rejected
/// (counted) with reanchor = true. When to restart time after either: StampAnchor. `mag_use`:
/// the filter's use_magnetometer (MagnetometerUse above).
inline SampleCheck check_imu_sample(const ImuSample& s, int64_t last_stamp_ns,
                                    const SampleLimits& lim, RejectCounters& counters,
                                    MagnetometerUse mag_use = MagnetometerUse::kAuto) {
  SampleCheck out;
  if (s.stamp_ns < 0 || s.stamp_ns > kMaxStampNs) {  // keeps every stamp difference in int64
    out.reject = RejectReason::kStampOutOfRange;
  } else if (!s.has_gyro) {
    out.reject = RejectReason::kMissingGyro;
  } else if (!s.has_accel) {
    out.reject = RejectReason::kMissingAccel;
  } else if (!s.has_mag && mag_use == MagnetometerUse::kRequired) {
    out.reject = RejectReason::kNoMagnetometer;
  } else {
    // finite norms within the limits have finite components (a non-finite one makes its norm inf
    // or NaN): the usual sample takes two norms; otherwise the tests in their order
    const double gyro_norm = s.gyro_rps.norm();
    const double accel_norm = s.accel_mps2.norm();
    const bool usable = std::isfinite(gyro_norm) && std::isfinite(accel_norm) && gyro_norm <= lim.max_gyro_rps &&
                        accel_norm <= lim.max_accel_mps2 && accel_norm >= lim.min_accel_norm_mps2;
    if (!usable) {
      out.reject = imu_values_reject(s, lim);
    }
  }
  if (out.reject != RejectReason::kCount) {
    counters.add(out.reject);
    return out;
  }
  const TimeStep step = time_step(s.stamp_ns, last_stamp_ns, lim.max_dt_s);
  if (step.kind == TimeStep::kNonMonotonic) {
    out.reject = RejectReason::kNonMonotonicStamp;
    counters.add(out.reject);
    return out;
  }
  if (step.kind == TimeStep::kGap) {
    out.reject = RejectReason::kTimeGap;
    counters.add(out.reject);
    out.reanchor = true;
    return out;
  }
  out.dt_s = step.dt_s;
  out.accept = true;
  if (mag_use == MagnetometerUse::kOff) {
    out.mag_absent = "use_magnetometer_false";
  } else if (s.has_mag) {
    // a finite norm within the limits has finite components: the usual reading takes one norm
    const double mag_norm = s.mag_ut.norm();
    if (std::isfinite(mag_norm) && mag_norm >= lim.min_mag_norm_ut && mag_norm <= lim.max_mag_ut) {
      out.mag_ok = true;
    } else {
      out.mag_reject = mag_value_reject(s.mag_ut, lim);
      if (out.mag_reject != RejectReason::kCount) {
        counters.add(out.mag_reject);
      } else {
        out.mag_ok = true;
      }
    }
  }
  return out;
}

/// A static pressure (Pa) against the barometer's plausible range [min_pa, max_pa]: kCount when
/// usable, else why not (counted in `counters`). A bad pressure refuses only the pressure.
inline RejectReason check_pressure(double pressure_pa, double min_pa, double max_pa,
                                   RejectCounters& counters) {
  RejectReason r = RejectReason::kCount;
  if (!std::isfinite(pressure_pa)) {
    r = RejectReason::kNonFinitePressure;
  } else if (!(pressure_pa >= min_pa && pressure_pa <= max_pa)) {
    r = RejectReason::kPressureOutOfRange;
  }
  if (r != RejectReason::kCount) {
    counters.add(r);
  }
  return r;
}

/// Restarting time after a stamp jump (a gap forward or a step back), shared by the IMU filters.
/// A jumping stamp is refused (check_imu_sample); time restarts at a stamp only when it follows
/// the previous refused one by (0, max_dt_s]: two samples must agree. So one wild stamp (the year
/// 292277026596, +1e15 ns) costs that one sample and the filter goes on with the next, while a
/// real restart of the sensor clock or a real pause costs one sample more than it did before.
struct StampAnchor {
  bool has_candidate = false;
  int64_t candidate_ns = 0;
  /// Call with every check result of `stamp_ns`; true: restart time at stamp_ns (do not integrate
  /// this sample).
  bool reanchor(const SampleCheck& c, int64_t stamp_ns, double max_dt_s) {
    if (c.accept) {
      has_candidate = false;
      return false;
    }
    if (c.reject != RejectReason::kNonMonotonicStamp && c.reject != RejectReason::kTimeGap) {
      return false;  // refused for its values: says nothing about time
    }
    // in double: two arbitrary int64 stamps can be further apart than int64 can hold
    const double dt_s = (static_cast<double>(stamp_ns) - static_cast<double>(candidate_ns)) * 1e-9;
    const bool agrees = has_candidate && dt_s > 0.0 && dt_s <= max_dt_s;
    has_candidate = !agrees;
    candidate_ns = stamp_ns;
    return agrees;
  }
};

}  // namespace poise
