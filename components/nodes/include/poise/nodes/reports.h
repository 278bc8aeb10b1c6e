// Pure conversions from estimator outputs to the attitude and diagnostics messages, shared by
// every estimator node (so each node stays a thin adapter: sample -> core -> report -> write).
#pragma once

#include "poise/core/heading_status.h"
#include "poise/core/source_report.h"

#include <poise/msg/diagnostics.h>
#include <poise/msg/estimates.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace poise::nodes {

/// What an attitude estimator reports after a step (SI, ENU, q_world_body).
struct AttitudeReport {
  int64_t stamp_ns = 0;  ///< stamp of the IMU sample the estimate is for
  uint32_t seq = 0;      ///< seq of that IMU sample (lets consumers match inputs and truth)
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< world small-angle error, rad^2
  Eigen::Vector3d ext_accel_body_mps2{0, 0, 0};
  Eigen::Vector3d ext_accel_world_mps2{0, 0, 0};
  Eigen::Vector3d mag_disturbance_body_ut{0, 0, 0};
  Eigen::Vector3d mag_disturbance_world_ut{0, 0, 0};
  double mag_disturbance_angle_rad = 0.0;
  bool mag_trusted = false;
  uint32_t sources_fused = 0;  ///< msg::SOURCE_* bits
  Eigen::Vector3d gyro_bias_rps{0, 0, 0};
  /// the core's heading_status() (msg::HEADING_*: the same values)
  HeadingStatus heading_status = HeadingStatus::kNoReference;
  std::string frame_id = "enu_magnetic";  ///< the world frame: enu_magnetic or enu_true (poise/core/north.h)
};

/// The one mapping of a Source to its msg::SOURCE_* bit (estimates.idl): gyro and yaw_rate
/// SOURCE_GYRO, accel and accel_tilt SOURCE_ACCEL, mag and mag_heading SOURCE_MAG, imu_quat
/// SOURCE_IMU_QUAT, vision_attitude and vision_position SOURCE_VISION, baro, speed; the rest
/// detectors' pseudo-measurements (zupt, zero_rate) carry no bit (0).
uint32_t source_bit(Source source);
/// msg::SOURCE_* bits of the sources a core fused at this step: the OR of source_bit() over the
/// reports whose decision is fused (at full or reduced weight, e.g. the selective EKF's heading
/// "inflated" while the magnetometer is untrusted: that is what mag_trusted tells apart).
uint32_t sources_fused_bits(const SourceReports& sources);
/// Whether the report of `source` is among `sources` and says fused (the nodes' mag_trusted:
/// the report of Source::kMag).
bool source_fused(const SourceReports& sources, Source source);

/// The heading status of a core that keeps none, from its magnetometer report at this step: fused
/// kVerified, rejected kUnverified, absent or not available kNoReference (the vehicle estimator).
HeadingStatus heading_status_from_mag(const SourceReports& sources);
/// The one mapping of the core's HeadingStatus to the IDL's HEADING_* (estimates.idl).
msg::HeadingStatus to_msg(HeadingStatus status);

/// Builds the message (roll/pitch/yaw ZYX from q, disturbance norm from the vector).
msg::AttitudeEstimate to_attitude_msg(const AttitudeReport& report, const std::string& sensor_id,
                                      const std::string& filter_id);

struct MetricReport {
  std::string name;
  double value = 0.0;
  std::string unit;
};

struct DiagnosticsReport {
  int64_t stamp_ns = 0;
  uint32_t seq = 0;
  std::string component;
  SourceReports sources;  ///< the core's report, mapped 1:1 (see to_diagnostics_msg)
  std::map<std::string, uint64_t> counters;
  std::vector<MetricReport> metrics;
};

/// Builds the message. Each SourceReport maps 1:1 onto msg::SourceStatus: fresh = a sample was
/// there (decision != not available), fused = decision fused, reason = the core's reason
/// ("not_available" when a not-available report gives none), last_fused_stamp_ns 0 = never.
/// Sequences longer than the IDL bounds are truncated and the truncation is
/// itself counted ("diagnostics_truncated"), never silently dropped.
msg::FilterDiagnostics to_diagnostics_msg(const DiagnosticsReport& report, const std::string& sensor_id);

}  // namespace poise::nodes
