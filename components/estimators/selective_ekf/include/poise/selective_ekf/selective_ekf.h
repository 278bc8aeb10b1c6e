// Selective EKF (paper 002, Yun/Shim/Kim): gyro + Gauss-Newton IMU quaternion + vision pose, with
// the IMU quaternion (i.e. the magnetometer) trusted only while the disturbance tests pass.
//
// Notation (ESTIMATORS.md section 4; equation numbers are paper 002's)
//   x = [w, q, b, t, v]  nominal state: body angular rate w (rad/s), q = q_world_body (ENU, Hamilton),
//                        gyro bias b (rad/s, extension: the paper has none), position t (m, world)
//                        and velocity v (m/s, world) of the body.
//   dx = [dw, dth, db, de, dt, dv]  18-dim error state; attitude error is body-frame (right)
//                        perturbation q_true = q (x) exp(dth). This error-state form carries the same
//                        selective behaviour as the paper's 13-dim form (accepted reading, section 4)
//                        and keeps P free of the quaternion norm direction. de (extension, kSplit): the
//                        accelerometer low-pass's error, a rotation in its almost inertial frame (below).
//   Process (3)-(4):     w, v, b random walks; q <- q (x) exp(w h); t <- t + v h.
//                        F: dth' = Exp(w h)^T dth + J_r(w h) h dw; dt' = dt + h dv;
//                        de' = de + R_ib J_r(w h) h dw (the low-pass's frame is turned with the same w),
//                        then de <- (1 - k) de at each low-pass step (gain k).
//                        Q: angular-acceleration and acceleration white noise (spectral densities),
//                        integrated over h (first order); the attitude's share enters de as R_ib times
//                        the same noise (fully correlated).
//   y = [w_gyro, q_imu | (tilt, heading), q_vision, t_vision]  (5)-(7): rows only when fresh.
//     gyro:      y = w + b + n,                   H = [I 0 I 0 0 0]
//     q_imu:     log(q^-1 (x) q_imu)  = dth + n,  H = [0 I 0 0 0 0]  (ImuMeasurement::kQuaternion: the
//                paper's Gauss-Newton quaternion, eq. 2)
//     ImuMeasurement::kSplit (default) replaces q_imu by two measurements so that a disturbed
//     magnetometer never costs tilt:
//     tilt:      z_up = the accelerometer low-passed (accel_lowpass_tau_s) in an almost inertial
//                frame turned with the state's rate w as the attitude is predicted, normalised; u =
//                R(q)^T e_z. Two rows e_i . (z_up x u) = e_i . (dth - R_ib^T de) (e_1, e_2 orthonormal,
//                perpendicular to u): the frame's error is the prediction's own error (the integrated
//                dw, gyro noise and bias error alike), and the low-pass keeps it less its low-passed
//                past (de). H = [0 e_i^T 0 -e_i^T R_ib^T 0 0]; a correction de turns the low-pass by
//                -de. Variance per
//                row: spectral density sigma_tilt^2 / h (sigma_tilt derived from
//                accel_lowpass_tau_s by default: see the parameter), inflated by the recent external
//                acceleration (| |a| - g | low-passed, see tilt_accel_ref_mps2).
//     heading:   dpsi = rotation about world up taking R(q) m (horizontal part) onto magnetic north
//                (+y ENU); one row dpsi = (u + tan(dip) R^T e_y) . dth (a tilted estimate turns the
//                field's horizontal projection), H = [0 (u + tan(dip) R^T e_y)^T 0 0 0 0], the tilt
//                considered (gain zeroed); variance sigma_heading^2 / h;
//                gated by the selective tests below: dip (8) against the filtered tilt within
//                heading_dip_tolerance_deg, |m| within heading_norm_tolerance, and quaternion
//                error (9) = |dpsi| only while vision anchors the heading (without vision the
//                predicted heading is the gyro's, and rejecting the magnetometer because it
//                disagrees with a drifting prediction locks the drift in).
//     rest:      at rest (rest detector on the raw gyro and accelerometer), the detector's
//                low-passed gyro y = b + n, H = [0 0 I 0 0 0], and (while w is consistent with rest
//                at 95 %) y = 0 = w + n_rest, H = [I 0 0 0 0 0] with the bias considered.
//     q_vision:  log(q^-1 (x) q_vis)  = dth + n,  H = [0 I 0 0 0 0]   q_vis = q_world_cam (x) q_body_cam^-1
//     t_vision:  p_world_cam = t + R(q) p_body_cam,  H = [0  -R [p_body_cam x]  0  0  I  0]
//     Measured quaternions are sign-aligned to the prediction before the innovation.
//   (7) printed P - K H^T P is read as P - K H P. R is diagonal, so the rows are fused one at a
//     time (exact): P <- P - u u^T / s with u = P h^T, s = h u + r (equal to the Joseph form for
//     this gain, symmetric by construction). q is renormalised after each update.
//   Disturbance angle (8): both vectors are rotated by the same matrix, so theta_m is the angle
//     between m and the up vector; up is the raw accelerometer (paper) or the filter's predicted up
//     R(q)^T e_z (UpSource::kFiltered, the VQF/PX4 improvement; only while vision anchors the tilt,
//     else raw: a gyro-only tilt would drift and lock the test). theta_ref = 90 deg + dip, dip learnt
//     from the first startup_samples (or configured). Disturbed when |theta_m - theta_ref| > threshold.
//     Optional extension (off by default): |m| against the learnt norm.
//   Quaternion error (9)-(10): dq = q_imu (x) q_pred^-1, theta_q = 2 acos(|dq_w|) (sign-invariant).
//   Selective: either test failing marks the magnetometer untrusted (kept for untrusted_hold_s after
//     the last failure); the q_imu rows are then inflated (R * inflate_factor) or dropped.
//     A quaternion-error failure alone stops counting after q_error_lockout_s when no vision was
//     fused within vision_anchor_s: without an absolute reference the prediction itself may be the
//     one that drifted (prevents lock-out).
//   Vision is applied at its capture time: a ring of post-update snapshots (one per IMU sample) and
//     the inputs after them are kept for history_s; a late measurement restores the snapshot at or
//     before its capture stamp, predicts to the capture stamp, fuses, and replays the later events
//     (IMU samples and other vision measurements, in stamp order). Out-of-order measurements are
//     handled the same way (counted); older than the history -> rejected (too_old).
//   6-axis input (ImuSample::has_mag false, the default: a sample has a magnetometer only when its
//     source says so; or use_magnetometer: false): the first attitude is the accelerometer's tilt with ZYX yaw 0
//     (quat_tilt_yaw0, the same start as every filter); the gyro then carries the heading (drifting
//     with the bias) unless vision fixes it.
#pragma once

#include "poise/core/attitude.h"
#include "poise/core/rest_detector.h"
#include "poise/core/attitude_filter.h"
#include "poise/core/north.h"
#include "poise/core/field_gate.h"
#include "poise/core/hard_iron.h"
#include "poise/core/sample_check.h"
#include "poise/core/source_report.h"
#include "poise/core/state_health.h"
#include "poise/core/types.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/selective_ekf/vision_time_offset.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <vector>

namespace poise {

/// Where the "up" vector of the disturbance-angle test (8) comes from.
enum class UpSource : uint8_t {
  kRawAccel = 0,  ///< paper: the measured accelerometer (contaminated by linear acceleration)
  kFiltered,      ///< the predicted up axis R(q)^T e_z while vision anchors the tilt (fused
                  ///< within vision_anchor_s), else the raw accelerometer
};

/// Which IMU attitude measurement is fused besides the gyro.
enum class ImuMeasurement : uint8_t {
  kSplit = 0,   ///< tilt from the low-passed accelerometer + heading-only magnetometer (default)
  kQuaternion,  ///< paper: one Gauss-Newton quaternion from accelerometer and magnetometer
};

/// What happens to the IMU quaternion rows while the magnetometer is untrusted.
enum class ImuQuatAction : uint8_t {
  kInflate = 0,  ///< measurement variance * inflate_factor
  kDrop,         ///< rows left out of the update
};

struct SelectiveEkfParams {
  // ---- process noise (continuous-time spectral densities)
  /// Angular-acceleration noise driving the w random walk, rad/s^2/sqrt(Hz). Higher: w follows the
  /// gyro faster (less smoothing); lower: more lag on fast motion.
  double sigma_angular_accel = 2.0;
  /// Acceleration noise driving the v random walk, m/s^2/sqrt(Hz).
  double sigma_linear_accel = 2.0;
  /// Extra attitude process noise, rad/sqrt(s) (model error of q <- q exp(w h)). 0 = paper.
  double sigma_attitude_walk = 0.002;

  /// Gyro-bias random walk, rad/s/sqrt(s) (MPU6050 bias instability is of order 0.01 deg/s over
  /// minutes; this allows ~0.5 deg/s drift per hour-scale). 0 = bias constant.
  double sigma_bias_walk = 2.0e-5;

  // ---- measurement noise (standard deviations)
  double sigma_gyro_rps = 0.01;        ///< gyro white noise, rad/s (GY-87 MPU6050 ~0.005-0.01)
  ImuMeasurement imu_measurement = ImuMeasurement::kSplit;
  /// kSplit: accelerometer low-pass time constant in the gyro-propagated frame, s. External
  /// accelerations average out over it while gravity (fixed in that frame) does not.
  double accel_lowpass_tau_s = 3.0;
  /// kSplit: tilt measurement noise spectral density, rad sqrt(s) (per-sample variance
  /// sigma^2 / h). With the attitude process noise q = sigma_attitude_walk^2 + sigma_gyro^2 h
  /// (rad^2/s) this sets the tilt's correction time constant, sigma_tilt / sqrt(q). NaN (default):
  /// derived so that the time constant is accel_lowpass_tau_s, sigma_tilt = tau sqrt(q) (0.0063 at
  /// 285 Hz and 0.0067 at 100 Hz with the defaults): the low-pass has removed the external
  /// accelerations that last less than tau, so correcting more slowly than that only leaves
  /// the gyro's drift in for longer, and correcting faster re-admits what the low-pass removed.
  double sigma_tilt_rad_sqrt_s = std::nan("");
  /// kSplit: external-acceleration scale of the tilt trust, m/s^2: the tilt variance is multiplied
  /// by 1 + (a_ext / tilt_accel_ref_mps2)^2 with a_ext the RMS of | |accel| - g | over
  /// accel_lowpass_tau_s. 0 = constant trust.
  double tilt_accel_ref_mps2 = 0.0;
  double gravity_mps2 = 9.81;          ///< g for the external-acceleration measure, m/s^2
  /// kSplit: the disturbance-angle test (8) tolerance, deg. The dip is measured against the
  /// filter's tilt (accurate with or without vision in kSplit), so the tolerance covers the
  /// magnetometer's calibration residue over orientations, not accelerometer contamination
  /// (disturbance_angle_threshold_deg, 3 deg, is the paper's value for kQuaternion).
  double heading_dip_tolerance_deg = 10.0;
  /// kSplit: | |m| / m_ref - 1 | above this: disturbed (0 = off). kQuaternion uses mag_norm_test.
  double heading_norm_tolerance = 0.05;
  /// kSplit: the magnetometer trust is the parallel KF's field gate (poise/core/field_gate.h): the
  /// reference |m| and dip are learnt over field_startup_s (|m| configured by field_magnitude_ut,
  /// the dip by dip_deg), then follow the accepted field with field_reference_tau_s; a field gated
  /// for field_reacquire_s that stayed stable (field_reacquire_tol) becomes the new reference;
  /// after field_max_reject_s of continuous rejection the magnetometer is used again. The same
  /// values as the parallel KF's mag_* keys.
  double field_magnitude_ut = std::nan("");  ///< uT; NaN = learnt
  double field_startup_s = 1.0;              ///< s
  double field_reference_tau_s = 100.0;      ///< s, 0 = fixed reference
  double field_reacquire_s = 20.0;           ///< s, 0 = never
  double field_reacquire_tol = 0.05;         ///< relative
  double field_max_reject_s = 60.0;          ///< s, 0 = never
  /// kSplit: a field reference learnt at start-up is provisional until the gate has accepted the
  /// field against it for this long, s (FieldGateParams::verify_s; the parallel KF's
  /// mag_verify_s). While provisional (and without vision anchoring the attitude) the heading is
  /// unverified and its published variance that of a heading uniform over +-180 deg, and a gated
  /// field that stays consistent for field_startup_s replaces the reference and restarts the
  /// heading on it (a cold start next to a magnet). 0 = verified when learnt (before).
  double field_verify_s = 5.0;
  /// kSplit: tilt and heading are fused every aiding_period_s (variance of the elapsed interval),
  /// not every sample: their information is in a seconds-long low-pass. 0 = every sample.
  double aiding_period_s = 0.02;
  /// kSplit: heading (magnetometer) measurement noise spectral density, rad sqrt(s).
  double sigma_heading_rad_sqrt_s = 0.04;
  /// kSplit: the heading variance is multiplied by 1 + w (r_norm^2 + r_dip^2), r = the field's
  /// deviation from the gate's reference over the gate's tolerance (1 at the gate): a field just
  /// inside the gate is trusted less than a clean one. 1: the variance doubles at the gate, where
  /// the deviation equals the tolerance (the tolerance is the scale of a field error the gate lets
  /// through). 0 = off.
  double heading_disturbance_weight = 1.0;
  /// kSplit: a hard-iron offset learnt online (poise/core/hard_iron.h, the parallel KF's
  /// hard_iron): a magnet fixed to the sensor adds a constant body-frame vector to every reading.
  /// Once known (converged, consistent, above min_applied_ut) it is removed from the reading the
  /// heading and the gate see; while it is there but not known yet (HardIronEstimator::pending())
  /// the field is not used and the gate is not asked (an offset against north reverses the
  /// horizontal field and passes the gate's norm and dip tests). Independently, with
  /// rest_detection, a field that moves while the sensor is at rest (FieldMovedAtRest, the gate's
  /// norm tolerance) is not used either. ImuMeasurement::kQuaternion (the paper's) has neither.
  bool hard_iron = true;
  /// The estimator's own parameters (YAML `hard_iron_estimator: {key: value}`, same key names).
  HardIronParams hard_iron_estimator;
  // ---- rest detection (zero-rate measurement, observes the gyro bias)
  bool rest_detection = true;
  double rest_gyro_max_rps = 2.0 * kRadPerDeg;  ///< rest if the low-passed |gyro| stays below, rad/s
  double rest_accel_max_mps2 = 0.5;   ///< ... and |accel - lowpass(accel)| stays below, m/s^2
  double rest_min_s = 1.5;            ///< ... for at least this long, s
  double rest_filter_tau_s = 0.5;     ///< low-pass time constant of the rest detector, s
  double sigma_rest_rate_rps = 0.002; ///< zero-rate measurement noise at rest, rad/s
  double sigma_imu_quat_deg = 3.0;     ///< Gauss-Newton quaternion, per axis, deg
  double sigma_vision_deg = 1.0;       ///< vision attitude per axis, deg (if the pose carries none)
  double sigma_vision_m = 0.01;        ///< vision position per axis, m (if the pose carries none)

  // ---- selective gating (paper eqs. 8-10)
  bool gating_enabled = true;          ///< false: q_imu always fused at sigma_imu_quat_deg
  UpSource up_source = UpSource::kFiltered;
  double dip_deg = std::nan("");       ///< NaN: learnt from the first startup_samples; else deg
  int startup_samples = 50;            ///< samples averaged for the dip (and |m|) reference
  double disturbance_angle_threshold_deg = 3.0;  ///< |theta_m - theta_ref| above: disturbed
  bool mag_norm_test = false;          ///< extension: also test |m| against the learnt norm
  double mag_norm_threshold = 0.1;     ///< relative | |m| / m_ref - 1 | above: disturbed
  bool quat_error_test = true;         ///< eqs. 9-10
  double quat_error_threshold_deg = 10.0;  ///< theta_q above: disturbed
  ImuQuatAction action = ImuQuatAction::kInflate;
  double inflate_factor = 1.0e4;       ///< variance multiplier when inflating
  /// stay untrusted this long after the last failed test, s (0: only while a test fails, as the
  /// parallel KF's gate; kSplit with the field gate: a hold only delays trusting a field the gate
  /// already accepts, and cost 5 deg of heading on BROAD trial 01)
  double untrusted_hold_s = 0.0;
  double q_error_lockout_s = 3.0;      ///< see notation block, s
  double vision_anchor_s = 1.0;        ///< vision fused this recently anchors the prediction, s

  // ---- vision
  double vision_gate_sigma = 5.0;      ///< reject a vision row when innov^2 > gate^2 * var
  int vision_reset_after_rejections = 10;  ///< consecutive rejections -> reset attitude/position
  double history_s = 0.5;              ///< oldest capture accepted (latency bound), s
  /// Camera-IMU time offset, s: a frame stamped t shows the pose at IMU time t + offset (Kalibr's
  /// timeshift convention, negative when the camera clock lags). Calibrated, e.g. by matching
  /// gyro-integrated rotation to the camera's rotation (docs/SELECTIVE_EKF.md). 0 = in sync.
  double vision_time_offset_s = 0.0;
  /// The offset's prior 1-sigma, s: > 0 estimates it online from the gyro and the camera's
  /// rotation (vision_time_offset.h, docs/SELECTIVE_EKF.md "Camera time offset"), starting from
  /// vision_time_offset_s; the vision attitude's variance is raised by (|w| sigma_offset)^2 while
  /// it is uncertain. 0 = vision_time_offset_s is exact, nothing estimated. Default 50 ms: a
  /// camera's stamp is seldom its exposure time (arrival, end of readout, its own clock: 10-50 ms
  /// off is common and unknown to its user), and estimating costs nothing when it is exact.
  double vision_time_offset_sigma_s = 0.05;
  /// How fast the estimated offset may change: random walk, s/sqrt(s).
  double vision_time_offset_walk_s_sqrt_s = 1.0e-4;
  /// Prediction horizon of predict_horizon(), s (the renderer's display time after the newest IMU
  /// sample; 0 = the pose at the newest sample, as q_world_body()), in [0, 0.2].
  double predict_horizon_s = 0.0;
  /// IMU group delay, s: the IMU's measurements describe the motion this long before their stamp
  /// (the sensor's internal low-pass filter; MPU6050 DLPF_CFG 3: ~4.8 ms; calibrated with
  /// `poise calibrate imu-delay` against a reference). The filter runs at stamp - delay, fuses
  /// vision at its (true) capture time, and outputs the attitude predicted to the sample stamp
  /// with the estimated rate. 0 = the stamps are the sampling instants of the motion. NaN
  /// (default; null in YAML) = not known: half the sample interval, the least delay any sampled
  /// sensor has (a sample is the mean over its interval): the state runs at the interval's middle
  /// and the output is predicted over half a sample, its covariance raised by the guess's error
  /// (dt^2 / 12) (R w)(R w)^T (the true delay uniform over none to one sample), as the parallel
  /// KF's. A delay the IMU's driver publishes (`imu_info`) or a configured one wins.
  double imu_delay_s = std::nan("");
  /// Output correction rate limit, deg/s: q_world_body() turns with the gyro (bias removed) and
  /// follows the state's estimate with corrections of at most this rate, so a large correction
  /// (vision back after a blackout) is a short glide, not a jump an AR renderer would show; small
  /// ones pass at once. Differences above 30 deg (a reset) are taken at once. 0 = the state.
  double output_max_correction_dps = 20.0;
  /// Published covariance only (attitude_covariance(); the estimate does not use it): the
  /// relative gyro scale error it allows for, per axis, each axis' independent of the others'. A
  /// scale error s_i turns the estimate by s_i times axis i's rotation the corrections have not
  /// caught up with yet (the rotation away from the attitude low-passed over the tilt's and the
  /// heading's correction lags). MPU6050: +-3 % uncalibrated; 0.5 % is the residue after a
  /// rate-table or turn calibration. 0 = none.
  double gyro_scale_error = 0.005;
  // ---- figures of the sensor (the estimate's error covariance P_err only; the gains never read
  // them, so the estimate is the same bit for bit whatever their value). NaN (default; null in
  // YAML) = not known: the design figures above stand in for them, as before. A datasheet gives
  // the densities (white noise, the -1/2 slope of the Allan deviation: sigma(T) = N / sqrt(T));
  // a sample of rate f then has the per-sample sigma N sqrt(f). docs/SELECTIVE_EKF.md "The
  // sensor's own figures".
  /// The gyro's white noise density, rad/s/sqrt(Hz). Known: the gyro row's noise in P_err is
  /// this over the sample interval (N^2 / h), and the attitude's noise is the gyro's alone (no
  /// sigma_attitude_walk: P_err's rate model has no residual); else sigma_gyro_rps and the walk.
  double gyro_noise_density_rps_per_sqrt_hz = std::nan("");
  /// The accelerometer's white noise density, m/s^2/sqrt(Hz). Known: the tilt rows' noise is
  /// the low-pass's own, carried in P_err's low-pass error e (AR(1): e <- (1 - k) e + k n, n the
  /// sample's noise as a rotation of the low-passed vector), the rows white-noise free, and a
  /// start at rest begins with the first sample's noise as the tilt's error (not
  /// init_sigma_attitude_deg); else the tilt density sigma_tilt counted as white noise per row.
  double accel_noise_density_mps2_per_sqrt_hz = std::nan("");
  /// The gyro's bias random walk, rad/s/sqrt(s) (the +1/2 slope of the Allan deviation; the
  /// parallel KF's key of the same name). Known: P_err's bias grows by it; else sigma_bias_walk.
  double gyro_bias_walk_rps_per_sqrt_s = std::nan("");
  Eigen::Quaterniond q_body_camera = Eigen::Quaterniond::Identity();  ///< camera -> IMU body
  Eigen::Vector3d p_body_camera_m{0.0, 0.0, 0.0};  ///< camera origin in the body frame, m

  // ---- initial uncertainty
  double init_sigma_attitude_deg = 10.0;
  double init_sigma_rate_rps = 0.1;
  double init_sigma_bias_rps = 0.01;   ///< initial gyro-bias uncertainty, rad/s (~0.6 deg/s)
  double init_sigma_position_m = 1.0;
  double init_sigma_velocity_mps = 1.0;

  SampleLimits limits;                 ///< IMU input validation (NaN, zero, dt)
  /// `use_magnetometer`: auto (default) = the magnetometer (heading, q_imu) when the sample carries
  /// one (ImuSample::has_mag); false = 6-axis even when it does (the gyro carries the heading); true
  /// = every sample must carry one (a sample without is refused, counted no_magnetometer).
  MagnetometerUse use_magnetometer = MagnetometerUse::kAuto;
  /// The q_imu source. 2 iterations from the previous estimate: on BROAD the benchmark figures are
  /// identical to 5 iterations (3 decimals) at ~60 % of the Gauss-Newton cost.
  GaussNewtonParams gauss_newton = [] {
    GaussNewtonParams g;
    g.max_iterations = 2;
    return g;
  }();

  /// Throws std::invalid_argument naming the key and its range (ParamCheck): validate(*this).
  void validate() const;
};

/// Loads SelectiveEkfParams from YAML (keys under `selective_ekf:` or at the top level, optional
/// nested `gauss_newton:`). Unknown keys and out-of-range values throw std::runtime_error naming
/// the file and key.
SelectiveEkfParams load_selective_ekf_params(const std::string& path);
/// Validates ranges; throws std::invalid_argument with a message naming the field.
void validate(const SelectiveEkfParams& p);
/// The kSplit heading's field gate parameters (heading_*_tolerance, field_*, dip_deg).
FieldGateParams heading_field_gate(const SelectiveEkfParams& p);

/// A camera pose from the tag map, stamped at capture (not arrival).
struct VisionPose {
  int64_t capture_stamp_ns = 0;
  Eigen::Quaterniond q_world_camera = Eigen::Quaterniond::Identity();
  Eigen::Vector3d p_world_camera_m{0.0, 0.0, 0.0};
  bool has_position = true;
  double sigma_rad = std::nan("");     ///< per-axis attitude std; NaN: params' default
  double sigma_m = std::nan("");       ///< per-axis position std; NaN: params' default
  /// The attitude's covariance as the camera computed it for this detection, world-frame rotation
  /// vector of the pose (rad^2; VisionPose.covariance's [rx ry rz] block). All zero = absent
  /// (sigma_rad then, isotropic); else it must be finite, symmetric and positive definite (a bad
  /// one is rejected, counted vision_bad_input) and it replaces sigma_rad in the update: a floor
  /// tag fixes the heading far better than the tilt, and an isotropic sigma threw that away.
  Eigen::Matrix3d attitude_covariance_world = Eigen::Matrix3d::Zero();
};

/// The filter's aid sources: one SourceStatus each (status()), the index of its status table.
enum class SelectiveEkfAid : uint8_t {
  kGyro = 0,
  kImuQuat,          ///< ImuMeasurement::kQuaternion only
  kVisionAttitude,
  kVisionPosition,
  kAccelTilt,        ///< ImuMeasurement::kSplit: low-passed accelerometer
  kMagHeading,       ///< ImuMeasurement::kSplit: magnetometer heading (gated)
  kZeroRate,         ///< rest detected: w = 0
  kCount
};
/// The aid's identity in reports and on the wire (to_string(Source) is its name).
Source source_of(SelectiveEkfAid a);

/// Why a source was or was not fused on its last sample.
enum class Decision : uint8_t {
  kNone = 0,            ///< no sample yet
  kFused,
  kFusedInflated,       ///< q_imu fused with inflated variance (magnetometer untrusted)
  kRejectedDisturbance, ///< q_imu dropped: disturbance-angle test (8) or |m| test
  kRejectedQuatError,   ///< q_imu dropped: quaternion-error test (9)-(10)
  kRejectedNoMag,       ///< no valid magnetometer in the sample (no q_imu)
  kRejectedGate,        ///< innovation test ratio > 1
  kRejectedBadInput,    ///< NaN / non-unit quaternion / bad stamp
  kRejectedTooOld,      ///< capture older than the history
  kReset,               ///< state reset to this measurement (after repeated gate rejections)
  kRejectedStateReset,  ///< the update left the state unhealthy: filter reset (state_health.h)
  kCount
};
const char* to_string(Decision d);

/// Per-source status (goes on the diagnostics topic).
struct SourceStatus {
  Eigen::Vector3d innovation{0.0, 0.0, 0.0};           ///< rad/s, rad or m
  Eigen::Vector3d innovation_variance{0.0, 0.0, 0.0};  ///< diagonal of H P H^T + R
  double test_ratio = 0.0;   ///< max over axes of innov^2 / (gate^2 var) (gate 1 when ungated)
  Decision last = Decision::kNone;
  uint64_t fused = 0;        ///< counters count first-pass decisions (not replays)
  uint64_t rejected = 0;
  int64_t last_fused_stamp_ns = -1;
  int64_t last_stamp_ns = -1;  ///< stamp of the last decision (any), -1 = none
  std::array<uint64_t, static_cast<size_t>(Decision::kCount)> by_decision{};
};

/// Magnetometer trust (the selective part).
struct MagStatus {
  bool trusted = true;
  bool angle_test_failed = false;
  bool norm_test_failed = false;
  bool quat_error_test_failed = false;
  double disturbance_angle_deg = 0.0;   ///< theta_m (8) of the last sample
  double reference_angle_deg = 0.0;     ///< 90 + dip
  double norm_ratio = 1.0;              ///< |m| / m_ref
  double quat_error_deg = 0.0;          ///< theta_q (9); kSplit: |heading innovation|
  bool reference_ready = false;         ///< dip (and |m|) learnt
  double dip_deg = 0.0;
  /// kSplit: the field was refused before the gate: a hard-iron offset not removable yet
  /// (hard_iron), or a field that moved at rest
  bool offset_pending = false;
  bool moved_at_rest = false;
  uint64_t untrusted_samples = 0;       ///< first-pass count
};

/// Vision bookkeeping.
struct VisionCounters {
  uint64_t received = 0;
  uint64_t applied = 0;
  uint64_t out_of_order = 0;     ///< capture older than a vision already applied (handled)
  uint64_t too_old = 0;          ///< rejected: capture before the history
  uint64_t bad_input = 0;        ///< rejected: NaN, zero quaternion, negative stamp
  uint64_t before_init = 0;      ///< rejected: no IMU sample yet
  uint64_t future = 0;           ///< capture after the last IMU sample: queued
  uint64_t replayed_imu_samples = 0;  ///< total IMU samples re-processed
};

/// Accelerometer low-pass (kSplit) and rest detector: filter state, so that replays reproduce it.
struct SelectiveEkfPreState {
  /// body -> almost inertial frame, turned with the state's rate w exactly as the attitude is
  /// predicted (predict_to): its error is the attitude's prediction error, so the low-pass's error
  /// is a linear function of the error state (the state e, kE: e' = R_ib J_r(w h) h dw, times
  /// 1 - k at each low-pass step; the tilt rows measure dth - R_ib^T e)
  Eigen::Quaterniond q_ib = Eigen::Quaterniond::Identity();
  Eigen::Vector3d lp_accel_i{0, 0, 0};  ///< low-passed accelerometer in that frame, m/s^2
  double ext_accel_ms = 0.0;            ///< low-passed (|a| - g)^2, (m/s^2)^2
  /// the samples' deviation from the low-pass (in its frame), itself low-passed over
  /// accel_lowpass_tau_s: the slow part (the low-pass's lag behind a frame that turns with the
  /// bias error) that ext_accel_error leaves to P_err, m/s^2
  Eigen::Vector3d deviation_lp{0, 0, 0};
  /// the first sample was not at rest (the rest detector's thresholds): the low-pass carries its
  /// external acceleration, as the initial attitude does (a start in motion)
  bool moving_start = false;
  double since_start_s = 0.0;           ///< time since the first sample, s
  /// the first sample's accelerometer noise is still to be added to P_err's tilt and e (a start
  /// at rest with accel_noise_density_mps2_per_sqrt_hz known: it needs an interval)
  bool start_noise_pending = false;
  /// such a start's external acceleration is not settled yet (settle_start): the first sample
  /// passed the one-sample rest test, which lets an acceleration across gravity through; the
  /// published covariance carries start_tilt_bound while it is not settled
  bool start_pending = false;
  /// the tilt error that acceleration can carry, rad^2 (the frame of the low-pass, which was the
  /// first sample's body frame: rest_start_tilt_variance across the first up vector)
  Eigen::Matrix3d start_tilt_bound = Eigen::Matrix3d::Zero();
  /// the first sample's weight left in the low-pass, prod (1 - k) since the start
  double start_lp_weight = 1.0;
  /// the moments of the samples' deviation d from the low-pass since the start, over time t since
  /// the start, for the straight line fitted to it (settle_start): int d dt (m/s^2 s),
  /// int d t dt (m/s^2 s^2), int t dt (s^2), int t^2 dt (s^3)
  Eigen::Vector3d start_dev_0{0, 0, 0};
  Eigen::Vector3d start_dev_1{0, 0, 0};
  double start_t_1 = 0.0;
  double start_t_2 = 0.0;
  RestDetector rest_detector;           ///< rest detected at the last sample: rest_detector.rest
};

/// What the published covariance adds to P (attitude_covariance(), src/published_covariance.cpp):
/// the errors the filter does not model, tracked with the samples (so replays reproduce them).
struct SelectiveEkfUnmodelled {
  /// the rotation the tilt's and the heading's corrections have not caught up with yet, per body
  /// axis (a gyro's scale error is its own on each axis): the world-frame rotation increments
  /// R e_i w_i dt high-passed over each correction lag, column i (rotation_tilt, world x, y, z) and
  /// its world-z component (rotation_heading, element i), rad; a scale error s_i of axis i turns
  /// the estimate by s_i times column i
  Eigen::Matrix3d rotation_tilt = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rotation_heading{0.0, 0.0, 0.0};
  /// the tilt rows' innovation as a world-frame rotation, low-passed over the tilt's correction
  /// lag: the accelerometer's disturbance the tilt is still following, rad
  Eigen::Vector3d tilt_innovation_lp{0.0, 0.0, 0.0};
  /// the tilt's error from the external acceleration the accelerometer low-pass lets through
  /// (ext_accel_error's attitude part, world x, y) squared, low-passed over the tilt's lag: its
  /// variance, rad^2 (accel_noise_density_mps2_per_sqrt_hz known; else zero)
  Eigen::Matrix2d ext_accel_power = Eigen::Matrix2d::Zero();
  /// the tilt's unmodelled errors above about magnetic north (world y: rotation_tilt's,
  /// tilt_innovation_lp's and ext_accel_error's tilt part) low-passed again over the heading's lag:
  /// the heading follows a tilt error about north through the dip only as its corrections average
  /// it, rad
  Eigen::Vector3d rotation_tilt_at_heading{0.0, 0.0, 0.0};  ///< rotation_tilt's world y per body axis
  double tilt_innovation_at_heading = 0.0;
  double ext_accel_at_heading = 0.0;
  double field_dn_lp = 0.0;    ///< |m| - reference of the fields used, low-passed over the heading lag, uT
  double field_dv_lp = 0.0;    ///< reference |m| (dip - reference dip), the same, uT
  double last_dt_s = 0.0;      ///< the last sample interval, s
};

/// The attitude predicted to a requested time (SelectiveEkf::predict).
struct PredictedAttitude {
  int64_t stamp_ns = -1;        ///< the instant it is predicted to (IMU clock)
  double horizon_s = 0.0;       ///< beyond the newest IMU sample's stamp, s
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< world-frame rotation vector, rad^2
  Eigen::Vector3d rate_rps{0.0, 0.0, 0.0};  ///< the body rate it was turned with (the state's w)
};

/// The filter state (inspectable; one snapshot per IMU sample in the history).
struct SelectiveEkfState {
  Eigen::Vector3d w_rps{0.0, 0.0, 0.0};
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();
  Eigen::Vector3d b_rps{0.0, 0.0, 0.0};  ///< gyro bias
  Eigen::Vector3d t_m{0.0, 0.0, 0.0};
  Eigen::Vector3d v_mps{0.0, 0.0, 0.0};
  Eigen::Matrix<double, 18, 18> P = Eigen::Matrix<double, 18, 18>::Identity();
  /// The covariance of the estimate's error (the published covariance's P): the same gains (from
  /// P) and the same measurements, but the process noise of a gyro whose sample is the rate's mean
  /// over its interval (predict_to): P's rate model leaves q h^3 / 12 per interval that no row
  /// sees, which keeps the gains as they were tuned and is not an error of the estimate. Updated
  /// with the Joseph form for P's gain, exact for any gain.
  Eigen::Matrix<double, 18, 18> P_err = Eigen::Matrix<double, 18, 18>::Identity();
  /// With accel_noise_density_mps2_per_sqrt_hz known: the error state [w, th, b, e, t, v] that the
  /// external acceleration the low-pass lets through causes, as the accelerometer shows it. P_err's
  /// model of the low-pass's noise (e <- (1 - k) e + k n_rot, preprocess) driven by the measured
  /// sample instead of the noise's statistics: n_rot = d x u / |lp|, d the gyro-carried sample
  /// less the low-pass; propagated with F and updated with P's gains like P_err (z <- z - K H z),
  /// so the filter's own response to it (docs/SELECTIVE_EKF.md "External acceleration"). Zero
  /// when the figure is not known.
  Eigen::Matrix<double, 18, 1> ext_accel_error = Eigen::Matrix<double, 18, 1>::Zero();
  /// kSplit: the world heading error, rad, that a body-fixed offset b (uT) left in the readings
  /// the heading row fused has put into the estimate is heading_per_offset . b. Driven by the
  /// heading row while its reading is not corrected (hard_iron not applied): the row's heading
  /// gain times the innovation's sensitivity to the reading, d dpsi / d m_body; every row's gain
  /// takes its share back (s <- (1 - u^T K H u) s, u = up in the body: the world heading's
  /// direction), the prediction leaves a world-frame heading error as it is. So it holds the
  /// heading row's averaging over the rotation, gyro-only stretches and vision's corrections
  /// (published_covariance.cpp, "offset").
  Eigen::Vector3d heading_per_offset{0.0, 0.0, 0.0};
  /// The same for the readings the hard-iron estimate corrected: their offset is b's estimate's
  /// error (covariance P_b), the heading error it put in heading_per_removed_offset . (b - b_hat)
  Eigen::Vector3d heading_per_removed_offset{0.0, 0.0, 0.0};
  /// The heading variance, rad^2, an offset the readings no longer carry left in the estimate:
  /// when the hard-iron estimate reopens (HardIronStep::kReset: the offset changed), the two terms
  /// above as they stood move here and both sensitivities restart at zero (they count only the
  /// readings of the new offset); every row's gain takes its share back ((1 - u^T K H u)^2, as
  /// the sensitivities).
  double offset_left_var = 0.0;
  int64_t stamp_ns = -1;                 ///< time of the state
  int64_t untrusted_until_ns = -1;       ///< magnetometer untrusted until (hold)
  int64_t q_error_fail_since_ns = -1;    ///< start of the current quaternion-error failure run
  int64_t last_vision_fused_ns = -1;
  bool vision_aligned = false;           ///< first vision has aligned the attitude
  /// P has cross-covariance between [w, th, b] and [t, v] (after a lever-arm position fix); while
  /// false the 9x9 and 6x6 blocks are propagated and updated separately (exactly, cheaper).
  bool coupled = false;
  bool position_aligned = false;
  int vision_consecutive_rejects = 0;
  int vision_pos_consecutive_rejects = 0;
  SelectiveEkfPreState pre;
  int64_t last_aiding_ns = -1;           ///< last tilt/heading fusion (kSplit)
  FieldGate field_gate;                  ///< kSplit: magnetometer reference and gate
  /// kSplit: the heading was started (or restarted) on a field the gate did not gate (learning,
  /// accepted or relearnt); false after a start on a gated field (a configured reference next to
  /// a magnet): the first accepted field then restarts it. heading_checked: the gate has judged
  /// the field the heading was started on.
  bool heading_anchored = false;
  bool heading_checked = false;
  /// kSplit, hard_iron: the body-fixed offset of the field, fed every sample with a magnetometer
  /// (the low-pass's frame q_ib as the gyro's rotation; in the state, so replays reproduce it)
  HardIronEstimator hard_iron = HardIronEstimator(HardIronParams{});
  /// kSplit, rest_detection: the field seen from q_ib's frame at rest; `held` the field moved at
  /// rest, held into the motion after it until the hard-iron estimate judged it (field_offsets)
  FieldMovedAtRest rest_field;
  bool mag_offset_pending = false;       ///< this sample's reading carries an offset not removable yet
  bool mag_moved_at_rest = false;        ///< this sample's field moved since the rest began (or is held)
  bool mag_corrected = false;            ///< this sample's reading had the offset removed
  SelectiveEkfUnmodelled unmodelled;     ///< the published covariance's own terms
};

/// Everything the selective EKF carries from one sample to the next besides its parameters: the
/// estimate (SelectiveEkfState), the Gauss-Newton source, the start-up reference, counters, the
/// per-source reports, the output blend and the history of snapshots and vision for late
/// measurements. Opaque (read it through the filter's accessors): take it with full_state(),
/// restore it with set_full_state() into a filter with the same parameters.
class SelectiveEkfFullState {
 public:
  /// One accepted IMU sample as the filter processes (and replays) it: the input of the aid
  /// sources (src/aid.h).
  struct ImuInput {
    int64_t stamp_ns = 0;
    Eigen::Vector3d gyro{0, 0, 0};
    Eigen::Vector3d accel{0, 0, 0};
    Eigen::Vector3d mag{0, 0, 0};
    bool has_q_imu = false;
    Eigen::Quaterniond q_imu = Eigen::Quaterniond::Identity();
    bool has_mag = false;
    double dt_s = 0.0;                  ///< sample interval (for spectral densities)
    // derived by preprocess() from the state's SelectiveEkfPreState (re-derived in replays)
    Eigen::Vector3d up_meas{0, 0, 1};   ///< kSplit: low-passed accelerometer direction (body)
    double tilt_var_scale = 1.0;        ///< kSplit: external-acceleration inflation
    double tilt_sigma = 0.0;            ///< kSplit: sigma_tilt_rad_sqrt_s (configured or derived)
    bool rest = false;
  };

 private:
  friend class SelectiveEkf;
  friend struct SelectiveEkfTestAccess;  ///< defined by tests only (e.g. to spoil the state)

  struct HistoryEntry {
    ImuInput input;
    SelectiveEkfState post;  ///< state right after processing `input` (before same-stamp vision)
  };

  GaussNewton gn_;
  SelectiveEkfState x_;
  bool initialized_ = false;
  bool out_ready_ = false;           ///< out_q_ holds a blended output
  Eigen::Quaterniond out_q_ = Eigen::Quaterniond::Identity();
  int64_t last_imu_stamp_ns_ = -1;   ///< stamp of the last accepted IMU sample (sensor clock)
  StampAnchor anchor_;               ///< time restarts after a stamp jump only when two samples agree
  RejectCounters rejections_;
  std::array<SourceStatus, static_cast<size_t>(SelectiveEkfAid::kCount)> status_{};
  MagStatus mag_;
  VisionCounters vc_;
  // start-up reference
  double dip_sum_rad_ = 0.0;
  double norm_sum_ut_ = 0.0;
  int ref_n_ = 0;
  double ref_angle_rad_ = 0.5 * kPi;
  double ref_norm_ut_ = 0.0;
  // history
  std::deque<HistoryEntry> history_;
  std::deque<VisionPose> vision_log_;    ///< applied or queued, sorted by capture stamp
  int64_t newest_vision_capture_ns_ = -1;
  StateHealth health_;  ///< resets after an unhealthy update (poise/core/state_health.h)
  VisionTimeOffsetEstimator time_offset_;  ///< the camera-IMU time offset (fed first-pass only)
};

class SelectiveEkf : private SelectiveEkfFullState {
 public:
  static constexpr int kN = 18;
  using Mat = Eigen::Matrix<double, kN, kN>;
  using Vec = Eigen::Matrix<double, kN, 1>;
  // error-state block offsets: [w, th, b, e] (attitude block, kAttN) then [t, v]; e is the
  // accelerometer low-pass's error (SelectiveEkfPreState)
  static constexpr int kW = 0;
  static constexpr int kTh = 3;
  static constexpr int kB = 6;
  static constexpr int kE = 9;
  static constexpr int kT = 12;
  static constexpr int kV = 15;
  static constexpr int kAttN = 12;

  explicit SelectiveEkf(const SelectiveEkfParams& params = {});

  /// One IMU sample (validated; rejected and counted when bad). Returns false when rejected, and
  /// when the update left the state non-finite or P not a covariance: the filter is then reset
  /// (counters kept), counted in state_resets() and starts again from the next sample (the
  /// same after update_vision()).
  bool update_imu(const ImuSample& s);
  /// One vision pose (capture-stamped, may arrive late or out of order). Returns false when it
  /// was rejected (bad input, too old, before the first IMU sample); the reason is counted.
  bool update_vision(const VisionPose& v);

  [[nodiscard]] bool initialized() const { return initialized_; }
  [[nodiscard]] const SelectiveEkfState& state() const { return x_; }
  /// The attitude at the stamp of the last IMU sample: state_output() with its corrections
  /// rate-limited to output_max_correction_dps (state_output() itself when 0).
  [[nodiscard]] Eigen::Quaterniond q_world_body() const;
  /// The state predicted over imu_delay_s with the estimated rate (the state itself when 0).
  [[nodiscard]] Eigen::Quaterniond state_output() const;
  /// The position at the stamp of the last IMU sample (predicted like q_world_body()).
  [[nodiscard]] Eigen::Vector3d position_m() const;
  [[nodiscard]] const SourceStatus& status(SelectiveEkfAid a) const {
    return status_[static_cast<size_t>(a)];
  }
  [[nodiscard]] const MagStatus& mag_status() const { return mag_; }
  [[nodiscard]] const VisionCounters& vision_counters() const { return vc_; }
  [[nodiscard]] const RejectCounters& imu_rejections() const { return rejections_; }
  /// Resets after an unhealthy state (poise/core/state_health.h).
  [[nodiscard]] uint64_t state_resets() const { return health_.resets; }
  [[nodiscard]] const SelectiveEkfParams& params() const { return p_; }
  /// Sets imu_delay_s (e.g. the delay the IMU's driver publishes; NaN = not known) before the
  /// first sample or after reset(): the state's time is the IMU stamp minus the delay. Throws
  /// std::invalid_argument outside [0, 0.05] s, std::logic_error once initialized.
  void set_imu_delay_s(double delay_s);
  [[nodiscard]] const GaussNewton& gauss_newton() const { return gn_; }
  /// Body-frame attitude standard deviations, deg (of the state's P).
  [[nodiscard]] Eigen::Vector3d attitude_sigma_deg() const;
  /// The published covariance of q_world_body(): world-frame rotation vector of q_true (x)
  /// q_est^-1, rad^2 (ENU x, y, z). The estimate's error covariance's attitude block
  /// (SelectiveEkfState::P_err: P's gains, a gyro sample the rate's mean) carried to the output (the delay
  /// prediction with the rate's covariance, the output blend's remaining correction) plus what
  /// the filter does not model (src/published_covariance.cpp, ESTIMATORS.md): the gyro bias error
  /// through the accelerometer low-pass's lag, the accelerometer disturbance the tilt is still
  /// following, the gyro scale error (gyro_scale_error) against the correction lags, and the field
  /// disturbance the gate lets through; and pi^2 / 3 on the heading (a heading uniform over
  /// +-180 deg) while heading_unknown(). The estimate itself never uses it.
  [[nodiscard]] Eigen::Matrix3d attitude_covariance() const;
  /// True while nothing bounds the heading (kSplit, field_verify_s > 0, no vision anchoring the
  /// attitude): the field reference is being learnt or is provisional, or the heading was started
  /// on a field the gate gated and no accepted field has restarted it yet.
  [[nodiscard]] bool heading_unknown() const;
  /// Whether the heading is backed by an absolute reference the filter trusts
  /// (poise/core/heading_status.h): kVerified while vision anchors the attitude (fused within
  /// vision_anchor_s: the tag map is one) or the magnetometer's heading row was fused trusted at
  /// its last step against a verified reference (FieldGate::verified: configured, or accepted for
  /// field_verify_s) with a heading that was not started on a gated field; kNoReference before the
  /// first sample and without a magnetometer or vision (6-axis: the gyro's heading); kUnverified
  /// otherwise: the reference still being learnt or provisional, the heading just restarted on a
  /// relearnt field, the magnetometer gated or distrusted. Meanwhile the heading
  /// variance of attitude_covariance() grows (P's own, and the gyro scale error over the whole
  /// rotation) and falls once a field is trusted again.
  [[nodiscard]] HeadingStatus heading_status() const;
  /// The heading's correction time constant now, s: the heading density the filter fuses (rad^2
  /// s, inflated while untrusted) over P's heading variance; infinite without a heading row.
  [[nodiscard]] double heading_lag_s() const;
  /// The heading variance, rad^2, of an offset the hard-iron estimate holds (converged) but does
  /// not remove (|b| at or below min_applied_ut, or not consistent), through the heading row's
  /// own gains (SelectiveEkfState::heading_per_offset): (s . b)^2 + s^T P_b s, the mean part only
  /// while the estimate is consistent (a body offset's; otherwise it fits a field that varies in
  /// space); 0 otherwise. Part of attitude_covariance(), with SelectiveEkfState::offset_left_var.
  [[nodiscard]] double unremoved_offset_var() const;
  /// The heading variance, rad^2, of the removed offset's error (hard_iron applied): s_r^T P_b s_r,
  /// s_r = SelectiveEkfState::heading_per_removed_offset, while the estimate is converged.
  [[nodiscard]] double removed_offset_var() const;
  /// The camera-IMU time offset in use (vision_time_offset_s, or its online estimate), its
  /// sigma, convergence and per-frame decisions (vision_time_offset.h).
  [[nodiscard]] const VisionTimeOffsetStatus& vision_time_offset() const { return time_offset_.status(); }
  /// The attitude predicted to t_ns (IMU clock, at or after the newest sample's stamp) with the
  /// estimated rate from q_world_body(), and its published covariance grown over the horizon
  /// (src/predict.cpp): the rate's covariance (gyro noise and bias uncertainty through the gyro
  /// row) and the angular-acceleration and attitude process noise. An earlier t_ns gives the
  /// newest output (horizon 0).
  [[nodiscard]] PredictedAttitude predict(int64_t t_ns) const;
  /// predict() at the newest sample's stamp + predict_horizon_s.
  [[nodiscard]] PredictedAttitude predict_horizon() const;
  /// Back to the state of a new filter (parameters kept).
  void reset();
  /// The filter's whole state: two filters with the same parameters and the same full state give
  /// the same outputs for the same samples (vision included).
  [[nodiscard]] const SelectiveEkfFullState& full_state() const { return *this; }
  /// Restores a state taken from full_state() of a filter with the same parameters.
  void set_full_state(const SelectiveEkfFullState& state) {
    static_cast<SelectiveEkfFullState&>(*this) = state;
  }

 private:
  void predict_to(int64_t stamp_ns);
  void process_imu(const ImuInput& in, bool first_pass);
  void process_vision(const VisionPose& v, bool first_pass);
  void learn_reference(const ImuSample& s);
  void replay_from(size_t snapshot_index);
  void blend_output(const Eigen::Vector3d& gyro_rps, double dt_s);
  void preprocess(ImuInput& in);
  /// kSplit: the hard-iron offset and the field moved at rest from this sample's raw reading
  /// (state flags for the heading aid); `in.mag` becomes the reading with the offset removed.
  void field_offsets(ImuInput& in);
  /// The published covariance's tracked terms after a step (SelectiveEkfUnmodelled); `aided`:
  /// tilt and heading were fused at this step over `aiding_dt_s`.
  void track_unmodelled(const ImuInput& in, bool aided, double aiding_dt_s);
  /// preprocess: the external acceleration's error (SelectiveEkfState::ext_accel_error) driven by a
  /// sample's deviation from the accelerometer low-pass (its gain k), with the accelerometer's figure
  void drive_ext_accel_error(const Eigen::Vector3d& deviation, double k, double dt_s);
  /// A start at rest: whether its first sample carried external acceleration, from the samples
  /// after it (selective_ekf.cpp).
  void settle_start(const ImuInput& in, const Eigen::Vector3d& deviation, double k, double dt_s);
  /// P_err += share times the start's tilt bound, its low-pass part weighted.
  void add_start_bound(double share);
  /// predict_to: the external acceleration's error by the prediction's F (a, b, e_w, interval h)
  void propagate_ext_accel_error(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b, const Eigen::Matrix3d& e_w,
                                 double h);
  // process_imu / process_vision run the aid sources (one file each: src/aid_*.cpp, shape and
  // declarations in the private header src/aid.h) on the state.
  SourceStatus& status_of(SelectiveEkfAid a);
  [[nodiscard]] bool healthy();
  void reset_unhealthy(int64_t stamp_ns);  ///< reset() keeping the counters, one reset counted
  /// Vision fused within vision_anchor_s of the state's time: the tag map anchors the attitude.
  [[nodiscard]] bool vision_anchors() const;

  SelectiveEkfParams p_;
  FieldGateParams gp_;  ///< heading_field_gate(p_)
  int64_t imu_delay_ns_ = 0;         ///< imu_delay_s when known (delay_ns())
  /// The delay in use, ns: imu_delay_s, or (not known) half the sample interval `dt_s`.
  [[nodiscard]] int64_t delay_ns(double dt_s) const;
  /// delay_ns() of the last sample (the state's time = its stamp - this).
  [[nodiscard]] int64_t current_delay_ns() const { return delay_ns(x_.unmodelled.last_dt_s); }
  [[nodiscard]] Eigen::Matrix3d output_error_covariance() const;  ///< P_err at the output (attitude_covariance)
  [[nodiscard]] double heading_row_density() const;  ///< the last magnetometer row's density, rad^2 s (attitude_covariance)
  /// the accelerometer's disturbance on the tilt and, through the dip, the heading (attitude_covariance)
  [[nodiscard]] Eigen::Matrix3d tilt_following(double q, double p_tilt, double g) const;
};

// ---- Reporting (selective_ekf_report.cpp): the core's outputs in the shapes every node maps 1:1.

/// Per source after the last step, in this order:
///   gyro, imu_quat, vision_attitude, vision_position: the core's SourceStatus (innovation rad/s,
///     rad or m; the decision's reason: fused "inflated" / "reset", rejected "disturbance",
///     "quat_error", "gate", "bad_input", "too_old"; not available "no_mag" / "no_sample").
///     A vision source whose last sample is older than vision_anchor_s before the state time is
///     not available ("no_recent_sample": e.g. the tag was lost).
///   (kSplit: imu_quat is "no_sample"; mag describes the heading row, thresholds
///   heading_dip_tolerance_deg / quat_error_threshold_deg.)
///   mag: the selective test of the magnetometer (eqs. 8-10): innovation [theta_m - theta_ref,
///     theta_q] (rad), variance the squared thresholds (test ratio > 1 = a test failed); rejected
///     "disturbance_angle", "field_norm", "quat_error" or "untrusted_hold" while untrusted, not
///     available "no_mag" / "learning_reference". Its counts are the IMU quaternion's fused at full
///     weight and the untrusted samples; its last fused stamp is the IMU quaternion's (while trusted).
///   accel_tilt, mag_heading, zero_rate: the kSplit rows' SourceStatus (not available
///     "no_sample" in kQuaternion; zero_rate only at rest).
SourceReports selective_ekf_sources(const SelectiveEkf& ekf);

/// World-frame attitude covariance (rad^2, small angles about ENU x, y, z): the published one,
/// ekf.attitude_covariance().
Eigen::Matrix3d attitude_covariance_world(const SelectiveEkf& ekf);

/// The 9x9 covariance [p, v, theta] (m^2, (m/s)^2, rad^2; theta world-frame small angles) of the
/// estimate's error covariance (SelectiveEkfState::P_err): blocks reordered, theta rotated by R(q).
Eigen::Matrix<double, 9, 9> pose_covariance_world(const SelectiveEkfState& x, const Eigen::Quaterniond& q_world_body);
/// The published pose covariance: pose_covariance_world(state, q_world_body()) with its attitude
/// block raised to the published attitude covariance (attitude_covariance_world): the difference
/// is added, its negative part (rounding, the delay prediction's small rotation) left out so that
/// the matrix stays positive semi-definite.
Eigen::Matrix<double, 9, 9> pose_covariance_world(const SelectiveEkf& ekf);

/// The filter's vision input from a camera pose measurement: per-axis std from the mean of the
/// covariance's position and rotation diagonals (NaN when not positive and finite: the params'
/// defaults then apply).
VisionPose to_vision_pose(const CameraPoseMeasurement& m);

/// AttitudeFilter adapter (IMU-only path; vision goes through core().update_vision()).
class SelectiveEkfFilter : public AttitudeFilter {
 public:
  explicit SelectiveEkfFilter(const SelectiveEkfParams& p = {}) : ekf_(p), delay_configured_(!std::isnan(p.imu_delay_s)) {}
  bool update(const ImuSample& s) override { return ekf_.update_imu(s); }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override { return ekf_.q_world_body(); }
  [[nodiscard]] bool initialized() const override { return ekf_.initialized(); }
  void reset() override { ekf_.reset(); }
  void seed_field(double field_ut, double dip_deg) override {
    SelectiveEkfParams p = ekf_.params();
    seed_field_reference(field_ut, dip_deg, p.field_magnitude_ut, p.dip_deg);
    ekf_ = SelectiveEkf(p);
  }
  [[nodiscard]] std::map<std::string, uint64_t> rejections() const override;
  [[nodiscard]] std::optional<Eigen::Matrix3d> attitude_covariance() const override;
  [[nodiscard]] HeadingStatus heading_status() const override { return ekf_.heading_status(); }
  [[nodiscard]] SourceReports sources() const override { return selective_ekf_sources(ekf_); }
  /// Used unless imu_delay_s was configured (not NaN): the state's time is the stamp minus the
  /// delay, so a running filter restarts on it (as the node does); throws std::invalid_argument
  /// outside [0, 0.05] s (set_imu_delay_s).
  bool take_published_imu_delay(double delay_s) override;
  [[nodiscard]] SelectiveEkf& core() { return ekf_; }
  [[nodiscard]] const SelectiveEkf& core() const { return ekf_; }

 private:
  SelectiveEkf ekf_;
  bool delay_configured_ = false;  ///< imu_delay_s was set by the parameters (a published one is ignored)
};

}  // namespace poise
