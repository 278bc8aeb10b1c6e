// Private to the selective EKF (src/): its aid sources, one file each (PX4 EKF2's layout), every
// one in the same shape:
//
//   1. validate    is there a usable measurement for this step? (else: a not-available or
//                  rejected decision, or nothing when the source has no sample at this step)
//   2. innovation  predict the measurement from the state: H, innovation, R (per-row variance)
//   3. gate        the source's own test: an innovation gate (vision), the magnetometer's
//                  selective test (heading, IMU quaternion: inflate or drop), none (gyro, tilt)
//   4. fuse        fuse(): one row at a time, or report_only for rows left out
//   5. status      record(): the decision, its stamp and the first-pass counters
//
// The filter (selective_ekf.cpp) owns the schedule: which aids run at a step, in which order,
// and with which derived inputs (preprocess: the low-passed up vector, rest, tilt density).
//
//   aid_gyro.cpp         gyro rows y = w + b (every IMU sample)
//   aid_zero_rate.cpp    zero-rate rows y = 0 = w (at rest)
//   aid_accel_tilt.cpp   tilt from the low-passed accelerometer (split mode)
//   aid_mag_heading.cpp  heading from the magnetometer (split mode), gated by mag_trust
//   aid_imu_quat.cpp     the Gauss-Newton quaternion (quaternion mode), gated by mag_trust
//   aid_vision.cpp       camera attitude and position (capture-stamped, replayed when late)
//   mag_trust.cpp        the selective test (8)-(10) the two magnetometer aids share
#pragma once

#include "update.h"

#include "poise/selective_ekf/selective_ekf.h"

namespace poise::selective_ekf_aids {

using ImuInput = SelectiveEkfFullState::ImuInput;

/// What every aid step is given: the state it corrects and the parameters. `first_pass` is false
/// while the filter replays samples after a late vision measurement (counters untouched).
struct AidContext {
  SelectiveEkfState& x;
  const SelectiveEkfParams& p;
  bool first_pass;
};

/// The magnetometer's selective test: its status and references.
struct MagTrust {
  MagStatus& status;
  const FieldGateParams& gate;  ///< split mode: the field gate in the state (x.field_gate)
  double ref_angle_rad;         ///< quaternion mode: theta_ref = 90 deg + dip (8)
  double ref_norm_ut;           ///< quaternion mode: |m| reference, 0 = not learnt
  /// split mode: what the field gate decided for the last sample (set by mag_trusted)
  FieldVerdict verdict = FieldVerdict::kAccepted;
};

void aid_gyro(const AidContext& c, const ImuInput& in, SourceStatus& st);
void aid_zero_rate(const AidContext& c, const ImuInput& in, SourceStatus& st);
void aid_accel_tilt(const AidContext& c, const ImuInput& in, SourceStatus& st);
/// `anchored`: vision fused within vision_anchor_s (the quaternion-error test needs it).
void aid_mag_heading(const AidContext& c, const ImuInput& in, bool anchored, MagTrust& mag, SourceStatus& st);
void aid_imu_quat(const AidContext& c, const ImuInput& in, bool anchored, MagTrust& mag, SourceStatus& st);

/// A vision pose prepared once for both vision aids: the body attitude it measures and the
/// per-axis standard deviations (the pose's own, else the parameters').
struct VisionMeasurement {
  int64_t stamp_ns = 0;  ///< capture stamp on the IMU clock
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();
  bool has_position = true;
  Eigen::Vector3d p_world_camera_m{0, 0, 0};
  double sigma_rad = 0.0;
  double sigma_m = 0.0;
  /// the pose's own attitude covariance (world frame, rad^2) when it carries one, else sigma_rad^2 I
  bool has_attitude_covariance = false;
  Eigen::Matrix3d attitude_covariance_world = Eigen::Matrix3d::Zero();
};
/// Whether a vision pose's attitude covariance is present (not all zero).
bool has_attitude_covariance(const VisionPose& v);
/// Whether a present attitude covariance is usable: finite, symmetric, positive definite.
bool attitude_covariance_ok(const Eigen::Matrix3d& c);
VisionMeasurement vision_measurement(const SelectiveEkfParams& p, const VisionPose& v);
/// src/vision_time_offset.cpp: the estimator's parameters from the filter's; the frame fed to
/// the offset estimator and moved onto the IMU clock with the offset in use (its variance raised
/// by (|w| sigma_offset)^2 while the offset is uncertain).
VisionTimeOffsetParams time_offset_params(const SelectiveEkfParams& p);
void apply_time_offset(VisionTimeOffsetEstimator& est, const SelectiveEkfParams& p, const Eigen::Vector3d& w_rps,
                       VisionPose& v);
void aid_vision_attitude(const AidContext& c, const VisionMeasurement& v, SourceStatus& st);
void aid_vision_position(const AidContext& c, const VisionMeasurement& v, SourceStatus& st);

/// Restarts the heading on the field (split mode, a relearnt field reference or the first field
/// the gate accepts after a start on a gated one): the attitude turned about world up by `dpsi`
/// (the field's heading innovation), P's heading direction (body `up`) decorrelated from the
/// rest and given the initial attitude variance, as at a start.
void restart_heading(const AidContext& c, const Eigen::Vector3d& up, double dpsi);

/// The heading row left out before the gate (split mode): the field carries a hard-iron offset
/// not removable yet or moved at rest (SelectiveEkf::field_offsets). The gate is not stepped (its
/// window still ticks); counted untrusted, reported rejected.
void refuse_field(const AidContext& c, const ImuInput& in, MagTrust& mag, SourceStatus& st);

/// The factor (>= 1) on the heading row's noise density sigma_heading^2 (split mode): raised as
/// the field nears the gate's tolerances (heading_disturbance_weight).
double heading_noise_factor(const SelectiveEkfParams& p, const FieldGate& gate, const FieldGateParams& gp);

/// The selective test (8)-(10) of the magnetometer for one sample, with `up` the up vector the
/// dip is measured against and `theta_q` the quaternion error (heading: |dpsi|). Updates the
/// trust state (hold, quaternion-error lock-out) and mag.status; returns whether it is trusted.
bool mag_trusted(const AidContext& c, MagTrust& mag, const ImuInput& in, const Eigen::Vector3d& up,
                 double theta_q, bool anchored);

}  // namespace poise::selective_ekf_aids
