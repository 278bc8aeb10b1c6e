// SourceReport: what every estimator core says about each of its inputs after a step, in one
// shape (STYLE.md habit 6; PX4 EKF2's per-aid-source status). Nodes map it 1:1 onto
// msg::SourceStatus; no adapter decides anything about a source.
//
//   source    which input (a typed Source, STYLE.md habit 16): to_string(Source) is its one wire
//             name (msg::SourceStatus.source); the nodes map it to the msg::SOURCE_* bits in one
//             switch (poise/nodes/reports.h source_bit), so a new Source does not compile until it
//             has a bit.
//   decision  kFused: the sample corrected the state; kRejected: a sample was there and the core
//             refused it (`reason` says why: a gate, a disturbance test, bad data); kNotAvailable:
//             no usable sample at this step (`reason`: no_sample, learning, not_used_by_method, ...).
//   innovation / innovation_variance  measurement - prediction and its variance, per component, in
//             the source's SI unit (m/s^2, uT, rad, m, m/s) and its square; empty when the core has
//             none for this source (e.g. the gyro drives the prediction).
//   test_ratio  innov^2 / (gate^2 var), max over components: > 1 means outside the gate; 0 when
//             ungated or not computed.
//   last_fused_stamp_ns  stamp of the last fused sample, -1 = never.
#pragma once

#include <Eigen/Core>

#include <algorithm>
#include <cstdint>
#include <vector>

namespace poise {

/// Every input a core reports on. The enumerators are the sources of all cores; a core reports
/// the ones it has, in a fixed order (its sources() / *_sources() documents which).
enum class Source : uint8_t {
  kGyro = 0,        ///< gyroscope (drives the prediction, or the selective EKF's rate rows)
  kYawRate,         ///< vehicle estimator: the gyro's yaw rate
  kAccel,           ///< accelerometer
  kAccelTilt,       ///< selective EKF (split): tilt from the low-passed accelerometer
  kMag,             ///< magnetometer (the selective EKF: its trust test, eqs. 8-10)
  kMagHeading,      ///< selective EKF (split): heading from the magnetometer
  kImuQuat,         ///< selective EKF (quaternion): the Gauss-Newton IMU quaternion
  kVisionAttitude,  ///< camera pose: attitude
  kVisionPosition,  ///< camera pose: position
  kBaro,            ///< barometer
  kSpeed,           ///< vehicle speed
  kZupt,            ///< altitude: zero-velocity pseudo-measurement at rest
  kZeroRate,        ///< selective EKF: zero-rate pseudo-measurement at rest
  kCount
};

/// The wire name (msg::SourceStatus.source); "unknown" only for kCount.
inline const char* to_string(Source s) {
  switch (s) {
    case Source::kGyro: return "gyro";
    case Source::kYawRate: return "yaw_rate";
    case Source::kAccel: return "accel";
    case Source::kAccelTilt: return "accel_tilt";
    case Source::kMag: return "mag";
    case Source::kMagHeading: return "mag_heading";
    case Source::kImuQuat: return "imu_quat";
    case Source::kVisionAttitude: return "vision_attitude";
    case Source::kVisionPosition: return "vision_position";
    case Source::kBaro: return "baro";
    case Source::kSpeed: return "speed";
    case Source::kZupt: return "zupt";
    case Source::kZeroRate: return "zero_rate";
    case Source::kCount: break;
  }
  return "unknown";
}

enum class SourceDecision : uint8_t { kNotAvailable = 0, kFused, kRejected };

inline const char* to_string(SourceDecision d) {
  switch (d) {
    case SourceDecision::kNotAvailable: return "not_available";
    case SourceDecision::kFused: return "fused";
    case SourceDecision::kRejected: return "rejected";
  }
  return "unknown";
}

/// Up to 6 components, no heap allocation (cores build the report every step).
using InnovationVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 6, 1>;

struct SourceReport {
  /// A report always names its source (never fused yet).
  explicit SourceReport(Source s) : source(s) {}

  Source source;
  SourceDecision decision = SourceDecision::kNotAvailable;
  /// Why it was rejected or not available (a static string); "" when fused normally, or a
  /// qualifier when fused in a reduced way (e.g. "inflated_disturbance").
  const char* reason = "";
  InnovationVector innovation;           ///< SI unit of the source
  InnovationVector innovation_variance;  ///< its square
  double test_ratio = 0.0;
  int64_t last_fused_stamp_ns = -1;
  uint64_t fused_count = 0;
  uint64_t rejected_count = 0;  ///< rejected samples (not-available steps are not counted)

  [[nodiscard]] bool fused() const { return decision == SourceDecision::kFused; }

  // Bookkeeping for the cores: one call per step and source (innovation set by the caller).
  void mark_fused(int64_t stamp_ns, const char* qualifier = "") {
    decision = SourceDecision::kFused;
    reason = qualifier;
    last_fused_stamp_ns = stamp_ns;
    ++fused_count;
  }
  void mark_rejected(const char* why) {
    decision = SourceDecision::kRejected;
    reason = why;
    ++rejected_count;
  }
  void mark_not_available(const char* why) {
    decision = SourceDecision::kNotAvailable;
    reason = why;
    innovation.resize(0);
    innovation_variance.resize(0);
    test_ratio = 0.0;
  }
  /// Gate statistics of a measurement: per-component innovation and variance, and the test ratio
  /// max_i innov_i^2 / (gate^2 var_i) (gate in standard deviations).
  void set_innovation(const InnovationVector& innov, const InnovationVector& var, double gate_sigma = 1.0) {
    innovation = innov;
    innovation_variance = var;
    test_ratio = 0.0;
    for (Eigen::Index i = 0; i < innov.size(); ++i) {
      if (var[i] > 0.0) {
        test_ratio = std::max(test_ratio, innov[i] * innov[i] / (gate_sigma * gate_sigma * var[i]));
      }
    }
  }
};

/// The reports of one step, one entry per input of the core (fixed order per core).
using SourceReports = std::vector<SourceReport>;

}  // namespace poise
