// ParallelKf: the parallel Kalman filter of paper 000 (J. K. Lee, "A Parallel Kalman Filter for
// Estimation of Magnetic Disturbance and Orientation Based on Nine-axis Inertial/Magnetic Sensor
// Signals", Trans. KSME A, 2016), eqs. 1-11, with switchable extensions.
//
// Notation (sensor/body frame S; world I = NWU inside the filter: X = horizontal magnetic north,
// Z = up, Y = Z x X = west; ENU at the interface: x_ENU = -y_NWU, y_ENU = x_NWU, z_ENU = z_NWU)
//   s_A, s_G, s_M   accelerometer (m/s^2), gyro (rad/s), magnetometer (uT)       (1a)-(1c)
//   sZ, sa          KF1 state: world up seen in S (unit), external acceleration  (4)   [TiltKf]
//   sX', sd         KF2 state: local field direction seen in S (unit, dip incl.),
//                   magnetic disturbance (uT)                                    (8)
//   g, m, alpha     gravity (m/s^2), field magnitude (uT), dip (rad)             (3a), (3b)
//   KF2: sX'_k = (I - h[s_G,k-1 x]) sX'_{k-1},  sd_k = c_d sd_{k-1} + eps_d      (9a), (9b)
//        F2, Q2 (Q22 uses |sd_{k-1}|^2: ESTIMATORS.md reading), H2 = [m I | I],
//        M2 = sigma_M^2 I                                                         (10), (11a)-(11h)
//   Combination: sY = normalise(sZ x sX'), sX = sY x sZ, sR = [sX sY sZ]          (2)
//   World quantities: ^I a = sR^T sa, ^I d = sR^T sd;  R_NWU_body = sR^T.
// m and alpha are not given by the paper: they are learnt over a start-up window (mean |s_M| and
// mean angle(s_A, s_M) - 90 deg) or configured, and reported.
//
// Extensions (each a switch in ParallelKfParams; all off in ParallelKfParams::paper()):
//   - gyro bias estimation: one Kalman filter (3x3 covariance) measured at rest by the low-passed
//     gyro and in motion by the rate of KF1's correction (the two components gravity makes
//     observable; the vertical one is left alone, Schmidt-style) and, while the field is trusted,
//     by the rate of KF2's heading correction; fast rotation inflates the motion noise by the
//     gyro's scale-factor uncertainty;
//   - magnetic disturbance gating: the heading update is skipped when | |s_M| - m | / m or
//     |dip(s_M, sZ) - alpha| exceed thresholds (the dip is measured against the filtered up sZ,
//     not the raw accelerometer, so external acceleration does not trip it); while gated, sd
//     follows s_M - m sX' so the disturbance output stays meaningful; after mag_reacquire_s of
//     continuous rejection with a stable field, the new field is adopted as the reference, and
//     after mag_max_reject_s the magnetometer is used again regardless (bounded heading drift);
//   - accelerometer low-pass (second-order Butterworth, time constant in s) in an almost inertial
//     (gyro-propagated) frame before KF1, so external accelerations average out while gravity
//     does not move (accel_lowpass_tau_s); KF1 then follows the low-passed vector closely;
//   - KF1's tilt correction applied to KF2's field direction as well (share_tilt_correction):
//     one attitude error moves both world directions seen in the body;
//   - trapezoidal propagation (gyro_current_weight; the paper uses k-1) with the coning of a rate
//     linear between samples (coning_correction), or of the quadratic through the last three
//     samples (quadratic_rate: what low rates need), and the output predicted
//     over the IMU's group delay (imu_delay_s, a calibrated property of the sensor);
//   - soft inflation of M2 as the field approaches the gate (mag_soft_weight, off: no gain);
//   - M2 inflated by the field disturbance KF2's own innovation shows beyond its white noise and
//     the attitude error (mag_adaptive_noise): a field turned in the room where the sensor moves
//     (BROAD 30: 2.113 -> 1.273 deg) pulls the heading with a longer lag;
//   - a hard-iron offset learnt online (hard_iron, poise/core/hard_iron.h: a magnet fixed to the
//     sensor) from the bias-corrected gyro and the raw s_M, removed from the s_M the gate and KF2
//     see once known, above 5 uT and consistent (removing it steadies the field's magnitude over
//     rotation); the heading variance then carries its uncertainty;
//   - exact rotation propagation, renormalisation, c_a/c_d defined at a reference rate.
// Measured on the 19 BROAD trials in ../shared/broad (mean total RMSE, undisturbed / disturbed;
// docs/ESTIMATORS.md "Figures at a glance"): paper 11.6 / 16.0 deg (first-order propagation lets
// |sZ| grow without bound at ~1000 deg/s); default with BROAD's calibrated IMU delay (imu_delay_s
// 4.18 ms) 1.138 / 1.256 deg at 285.7 Hz, 1.142 / 1.287 at 95.2 Hz, 1.204 / 1.856 at 40.8 Hz; with
// no delay known (half a sample assumed) 1.228 / 1.385. The Gauss-Newton baseline: 34.5 / 62.3 deg.
// Bad input (NaN, zero vectors, non-monotonic stamps, gaps) is rejected and counted; the state is
// untouched (a gap re-anchors time).
// 6-axis input (ImuSample::has_mag false, the default: a sample has a magnetometer only when its
// source says so; or use_magnetometer: false): heading is not observable. The filter starts at
// ZYX yaw 0 for the accelerometer's tilt (quat_tilt_yaw0, the same start as every filter) and
// KF2 then carries that north (horizontal, no dip) propagated by the gyro and tilt-corrected like
// sX', never corrected by a field: the heading follows the gyro, drifting with its bias (as the
// selective EKF's). The first magnetometer sample (use_magnetometer: auto) restarts KF2 on the
// field. use_magnetometer: true refuses every sample without a magnetometer (no_magnetometer).
#pragma once

#include "poise/core/attitude.h"
#include "poise/core/attitude_filter.h"
#include "poise/core/north.h"
#include "poise/core/field_gate.h"
#include "poise/core/hard_iron.h"
#include "poise/core/lowpass.h"
#include "poise/core/rest_detector.h"
#include "poise/core/sample_check.h"
#include "poise/core/source_report.h"
#include "poise/core/state_health.h"
#include "poise/core/types.h"
#include "poise/parallel_kf/direction_kf.h"
#include "poise/parallel_kf/tilt_kf.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace poise {

/// Parameters. The struct defaults are the shipped `default` configuration (most accurate on
/// BROAD); `paper()` is the faithful one. Every field: unit, and what raising it does.
struct ParallelKfParams {
  /// KF1 defaults of the shipped configuration. KF1 is corrected with the accelerometer
  /// low-passed in an almost inertial frame (accel_lowpass_tau_s), so its measurement noise is the
  /// residual of that low-pass, not the raw sensor noise: sigma_A 0.0003 m/s^2 against sigma_G
  /// 0.086 deg/s gives KF1 a correction time constant of about 0.03 s (sqrt(2) sigma_A / (g
  /// sigma_G)), negligible against the low-pass's 3 s, so the low-pass alone sets the tilt. c_a = 0: the
  /// low-passed vector's external-acceleration residual is treated as white (independent of rate).
  static TiltKfParams default_tilt() {
    TiltKfParams t;
    t.sigma_gyro_rps = 0.0015;
    t.sigma_accel_mps2 = 0.0003;
    t.c_a = 0.0;
    return t;
  }
  // --- KF1 (tilt) and KF2 (heading) noise model (paper 000 Table 1 / eqs. 7, 11)
  TiltKfParams tilt = default_tilt();    ///< KF1 parameters (sigma_G, sigma_A, c_a, ...)
  double sigma_gyro_heading_rps = 0.05 * kRadPerDeg;  ///< sigma_G for KF2, rad/s (0 = same as tilt.sigma_gyro_rps). Raising: faster heading correction.
  double sigma_mag_ut = 0.4;             ///< sigma_M, uT (HMC5883L: 2 mG = 0.2 uT). Raising: slower heading correction.
  /// Disturbance model coefficient (9b), [0, 1), per step (see c_d_rate_hz). Default 0: the
  /// disturbance seen by an accepted magnetometer sample is re-estimated at every sample (white),
  /// which is the same at every rate; the paper's 0.1 per step is a time constant tied to its
  /// 100 Hz (persistent disturbances are handled by the gating below instead).
  double c_d = 0.0;
  double c_d_rate_hz = 0.0;              ///< > 0: c_d given at this rate and scaled to dt
  double sigma_gyro_extra_heading_rps = 0.0;  ///< extra gyro error std in Q21, rad/s

  // --- field reference (m, dip)
  double field_magnitude_ut = std::nan("");  ///< m, uT; NaN = learn at start-up
  double dip_deg = std::nan("");             ///< alpha, deg; NaN = learn at start-up
  double startup_s = 1.0;                    ///< start-up window for learning m and alpha, s

  // --- propagation
  /// Propagation rate w = (1 - x) s_G,k-1 + x s_G,k: 0 = the paper's s_G at k-1 (7a), 0.5 =
  /// trapezoid (the rate over (k-1, k] as the mean of its two end samples: no lead or lag of its
  /// own, so the whole state describes the sensor's time; the sensor's group delay is then
  /// compensated by imu_delay_s alone), 1 = the current sample (leads by half a sample).
  double gyro_current_weight = 0.5;
  /// With the trapezoid (gyro_current_weight 0.5) and exact rotation: the step's rotation is that
  /// of a rate linear between the two samples, h (w1 + w2) / 2 + (h^2 / 12) w1 x w2 (the second
  /// term is the coning of a rotation axis that moves during the step; it grows with (|w| h)^2,
  /// so it matters at low rates: 40.8 Hz BROAD undisturbed 2.264 -> 2.020 deg, docs/ESTIMATORS.md).
  bool coning_correction = true;
  /// With the coning term: the rate over (k-1, k] is the quadratic through the last three
  /// samples (k-2, k-1, k) instead of the line through the last two, and the step's rotation that
  /// of that rate (its integral and its coning, both closed form). The trapezoid misses
  /// h^3 w'' / 12 of the rotation per step: a rate that curves within the step (a hand turning
  /// back and forth at a few Hz) sampled at tens of Hz leaves the gyro-only frame, and with it the
  /// accelerometer's low-pass and the tilt, that far off (docs/ESTIMATORS.md "The rate between
  /// samples"). Used when the two last intervals differ by at most a factor of two (else the line),
  /// with exact rotation and the trapezoid (gyro_current_weight 0.5). Off in paper().
  bool quadratic_rate = true;
  /// IMU group delay, s: the sensor's samples describe the motion this long before their stamp
  /// (its internal low-pass; MPU6050 DLPF_CFG 3: about 4.8 ms). The output is predicted over it
  /// with the bias-corrected gyro, q_world_body = q (x) exp(w delay); the filter state is not
  /// touched. Calibrated per sensor (`poise calibrate imu-delay` against a reference), or
  /// published by the IMU's driver (`imu_info`). 0 = none. NaN (the default; `null` in YAML) = not
  /// known: half the sample interval, the least delay a sampled sensor has (a sample is at best
  /// the mean over the interval that ends at its stamp, centred half an interval before it; the
  /// current-sample propagation before the trapezoid assumed exactly this without saying so).
  double imu_delay_s = std::nan("");

  // --- accelerometer low-pass in an almost inertial frame (extension)
  /// > 0: KF1 is corrected with the accelerometer low-passed with this time constant (s) in a
  /// gyro-propagated frame (external accelerations average out, gravity does not move), 0 = paper.
  /// A ramp (e.g. a residual gyro bias) is followed with a lag of tau seconds.
  double accel_lowpass_tau_s = 3.0;
  /// Order of that low-pass: 2 = Butterworth (-40 dB/decade, same lag), 1 = first order.
  int accel_lowpass_order = 2;
  /// Apply KF1's tilt correction (the small rotation that moved sZ) to KF2's field direction sX'
  /// too: both are world directions seen in the same body, so one attitude error moves both.
  /// Without it sX' keeps the gyro's tilt drift until the magnetometer removes it, and near the
  /// vertical field (dip 60-70 deg) a tilt error of sX' about north turns the heading by
  /// tan(dip) times as much. Off in the paper configuration.
  bool share_tilt_correction = true;

  // --- gyro bias estimation (extension)
  bool bias_estimation = true;
  double rest_gyro_max_rps = 2.0 * kRadPerDeg;  ///< rest if the low-passed |s_G| stays below, rad/s
  double rest_accel_max_mps2 = 0.5;             ///< ... and |s_A - lowpass(s_A)| stays below, m/s^2
  double rest_min_s = 1.5;                      ///< ... for at least this long, s
  double rest_filter_tau_s = 0.5;               ///< low-pass time constant of the rest detector, s
  // The bias estimate at rest is a Kalman filter with the low-passed gyro as its measurement: its
  // variance starts at bias_sigma_init_rps^2 (so the first rest averages fast), grows by
  // bias_drift_rps^2 per bias_forgetting_time_s while not observed, and its measurement noise is
  // set so that continuous rest settles at bias_sigma_rest_rps (the low-passed samples are
  // correlated, so they are not independent measurements). The same at every rate.
  double bias_sigma_init_rps = 0.5 * kRadPerDeg;   ///< initial bias uncertainty, rad/s
  double bias_sigma_rest_rps = 0.03 * kRadPerDeg;  ///< steady-state uncertainty at rest, rad/s. Raising: faster, noisier.
  double bias_drift_rps = 0.1 * kRadPerDeg;        ///< bias change expected over bias_forgetting_time_s, rad/s
  double bias_forgetting_time_s = 100.0;           ///< s
  /// The gyro's own bias instability, as a random walk of this density, rad/s/sqrt(s): a property
  /// of the sensor (its Allan deviation's rate random walk K, the +1/2 slope; a simulated gyro
  /// says what it draws), not of the filter. Only the published covariance uses it: the bias
  /// estimate's real error (bias_err_cov) grows by its square per second. The estimate is the
  /// same whatever its value (the bias filter keeps bias_drift_rps per bias_forgetting_time_s,
  /// its design). NaN (the default; `null` in YAML) = not known: the design drift is taken as
  /// the real one (bias_drift_rps / sqrt(bias_forgetting_time_s): 0.01 deg/s/sqrt(s), 1.75e-4
  /// rad/s/sqrt(s)). In [0, 0.01] rad/s/sqrt(s) otherwise (docs/ESTIMATORS.md "The gyro's bias
  /// walk": where the figure comes from).
  double gyro_bias_walk_rps_per_sqrt_s = std::nan("");
  /// The spread of the gyro's bias when the filter starts (its turn-on bias, the datasheet's
  /// zero-rate offset tolerance as one sigma per axis, or what a simulated gyro draws), rad/s: a
  /// property of the sensor, not of the filter. Only the published covariance uses it: the bias
  /// estimate's real error (bias_err_cov) starts at its square, and with it the attitude error
  /// the unknown bias leaves before the first rest has measured it (lag_cov), which the lags then
  /// forget over tens of seconds. The estimate is the same whatever its value (the bias filter
  /// starts at bias_sigma_init_rps, its design: the first rest averages fast). NaN (the default;
  /// `null` in YAML) = not known: bias_sigma_init_rps taken as the sensor's. In [0, max_bias_rps]
  /// otherwise (docs/ESTIMATORS.md "The gyro's bias at start").
  double gyro_initial_bias_sd_rps = std::nan("");
  /// The gyro's white noise density, rad/s/sqrt(Hz): a property of the sensor (its Allan
  /// deviation's angle random walk N, the -1/2 slope; per-sample sigma = density * sqrt(rate)),
  /// not of the filter. Only the published covariance uses it: the noise of the bias filter's
  /// measurements in bias_err_cov (the mean of a window of t seconds: density^2 / t). NaN (the
  /// default; `null` in YAML) = not known: sigma_gyro_heading_rps taken as the per-sample sigma at
  /// the filter's rate. In [0, 0.1] rad/s/sqrt(Hz) otherwise.
  double gyro_noise_density_rps_per_sqrt_hz = std::nan("");
  /// Gyro bias in motion (0 = off): the same Kalman filter is also measured while moving, by the
  /// rate at which KF1's correction turns sZ (the part of the attitude change that the gyro did
  /// not explain; only the two components perpendicular to gravity are observable), with the lag
  /// of the accelerometer low-pass compensated. Its measurement noise is set so that continuous
  /// motion settles the bias uncertainty at this value (as bias_sigma_rest_rps at rest), rad/s:
  /// motion is a worse bias sensor than rest, so it is larger. Raising: faster, noisier.
  double motion_bias_sigma_rps = 0.1 * kRadPerDeg;  // VQF's published biasSigmaMotion
  /// Also measure the component about the vertical from accepted magnetometer updates (the
  /// heading correction rate), only while the field is trusted (not gated).
  bool motion_bias_heading = true;
  /// Bias disagreements larger than this (rad/s) are clipped before the motion update, so a
  /// fast rotation with a mis-scaled gyro or an unmodelled acceleration cannot throw the bias.
  double motion_bias_clip_rps = 2.0 * kRadPerDeg;
  /// Relative gyro scale-factor uncertainty (after calibration). While turning at w, a scale
  /// error shows as a "bias" of up to scale * |w|: the motion measurement's noise grows by
  /// (motion_gyro_scale_error * |w|)^2 (|w|^2 low-passed over accel_lowpass_tau_s, the window
  /// the measurement sees), so fast rotation barely moves the bias while slow motion still does.
  /// With the accelerometer low-pass, |w|^2 is |LP(R_ib w)|^2: the rate vector low-passed over
  /// tau in the almost inertial frame (what KF1's correction carries of a scale error).
  double motion_gyro_scale_error = 0.005;
  /// The gyro's own scale-factor error (relative, after calibration): a property of the sensor (a
  /// simulated gyro has none), not of the filter. Only the published covariance uses it: the
  /// attitude error s dtheta a scale error s leaves (the `gyro_scale` term). NaN (the default;
  /// `null` in YAML) = not known: motion_gyro_scale_error, the bias filter's design figure, taken
  /// as the sensor's. In [0, 1) otherwise. The estimate is the same whatever its value.
  double gyro_scale_error = std::nan("");
  double max_bias_rps = 3.0 * kRadPerDeg;       ///< clamp of the bias estimate, rad/s

  // --- magnetic disturbance gating of the heading update (extension)
  bool mag_gating = true;
  /// Relative | |s_M| - m | / m above which s_M is rejected. 5 % chosen by leave-one-trial-out
  /// cross-validation on BROAD (`poise eval broad --grid mag_norm_tol=...`; docs/ESTIMATORS.md).
  double mag_norm_tol = 0.05;
  double mag_dip_tol_deg = 10.0;    ///< |dip - alpha| above which s_M is rejected, deg
  /// The reference norm and dip follow the accepted field with this time constant (s, over
  /// accepted time; 0 = fixed after start-up): a slow change of the field is adopted, a fast one
  /// is gated. 100 s chosen in 18 of 19 folds of leave-one-trial-out on BROAD (docs/ESTIMATORS.md).
  double mag_reference_tau_s = 100.0;
  double mag_reacquire_s = 20.0;    ///< adopt a stable new field after this long rejected, s (0 = never)
  double mag_reacquire_tol = 0.05;  ///< relative stability of the candidate field for adoption
  /// After this long of continuous rejection the magnetometer is used again even though it fails
  /// the gate (bounds the gyro-only heading drift in a permanently changed field), s. 0 = never.
  double mag_max_reject_s = 60.0;
  /// A field reference learnt at start-up is provisional until the gate has accepted the field
  /// against it for this long, s (FieldGateParams::verify_s; 0 = verified when learnt, the paper).
  /// While provisional the heading is unverified and its variance that of a heading uniform over
  /// +-180 deg, and a gated field that stays consistent for startup_s replaces the reference and
  /// restarts the heading on it (a cold start next to a magnet). Also: with no field used for this long
  /// (gated, or refused before the gate: moved at rest, an offset not yet removable), the heading
  /// is unverified (its variance grows with the gyro's). 5 s: a magnet near a handheld
  /// device changes the field within seconds of motion, and a start-up field that held that long
  /// is taken as the Earth's; shorter than mag_reacquire_s, the gate's patience with a verified one.
  double mag_verify_s = 5.0;
  /// > 0: below the gate, sigma_M^2 is inflated by weight * sigma_M^2 * (r_norm^2 + r_dip^2), r =
  /// deviation / tolerance (soft weighting of a nearly disturbed field). 0 = off.
  double mag_soft_weight = 0.0;
  /// With mag_gating: KF2 weighs an accepted field against the disturbance its own innovation
  /// shows. The heading variance a rotated field leaves (field_rotation_var: KF2's innovation about
  /// the vertical, low-passed over KF2's lag, beyond what white noise and the attitude error
  /// explain) is a lower bound of that field's disturbance variance (the low-pass |H| <= 1 passes
  /// at most all of it); it is added to the heading's measurement noise (Mehra's innovation-based
  /// R, its certain part only). A field turned where the sensor moves (a magnet in the room) then
  /// pulls the heading with a longer lag; a clean field leaves no excess and the gain is as before.
  /// Not for a reading with a hard-iron offset removed (its error is the filter's own). Off in
  /// paper(). docs/ESTIMATORS.md "A field turned in the room".
  bool mag_adaptive_noise = true;

  // --- hard-iron offset (extension; poise/core/hard_iron.h)
  /// Learn a body-fixed field offset b online (a magnet attached to the sensor) from the
  /// bias-corrected gyro and the raw magnetometer, and remove it from the reading the gate and
  /// KF2 see once it is known (every axis' sigma < converged_sigma_ut), |b| > min_applied_ut and
  /// consistent (HardIronParams::consistency_tau_s); while removed, the heading variance carries b's remaining uncertainty.
  /// BROAD (docs/ESTIMATORS.md "Hard-iron offset"): 1.151 / 1.870 -> 1.151 / 1.454 deg in-sample.
  bool hard_iron = true;
  /// The estimator's own parameters (YAML `hard_iron_estimator: {key: value}`, same key names).
  HardIronParams hard_iron_estimator;

  SampleLimits limits;              ///< input validation
  /// `use_magnetometer`: auto (default) = the magnetometer when the sample carries one
  /// (ImuSample::has_mag); false = 6-axis even when it does (heading from the gyro alone); true =
  /// every sample must carry one (a sample without is refused, counted no_magnetometer).
  MagnetometerUse use_magnetometer = MagnetometerUse::kAuto;

  /// The faithful paper configuration (Table 1 noise, c_a = c_d = 0.1 per step, no extensions).
  static ParallelKfParams paper();
  /// The shipped default (same as a default-constructed struct).
  static ParallelKfParams defaults() { return {}; }
  /// Named configuration: "paper" or "default". Throws std::invalid_argument otherwise.
  static ParallelKfParams named(const std::string& name);
  /// Throws std::invalid_argument naming the first out-of-range field.
  void validate() const;
  /// The magnetic field gate's parameters (mag_gating, field_magnitude_ut, dip_deg, startup_s,
  /// mag_*), as the shared gate takes them (poise/core/field_gate.h).
  [[nodiscard]] FieldGateParams field_gate() const;
};

/// Loads parameters from YAML: optional `preset: paper|default` (base; without it `base`), then
/// any field by name (nested under `parallel_kf:` or at the top level; `tilt.x` or `tilt: {x: }`).
/// Unknown keys and out-of-range values are errors (std::runtime_error naming the file and key).
ParallelKfParams load_parallel_kf_params(const std::string& path,
                                         const ParallelKfParams& base = ParallelKfParams{});

/// Everything the filter reports after a step.
struct ParallelKfOutput {
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();  ///< ENU
  Eigen::Vector3d rpy_rad{0, 0, 0};                ///< roll, pitch, yaw (ZYX, ENU yaw), rad
  Eigen::Vector3d ext_accel_body_mps2{0, 0, 0};    ///< sa
  Eigen::Vector3d ext_accel_world_mps2{0, 0, 0};   ///< ENU
  Eigen::Vector3d mag_dist_body_ut{0, 0, 0};       ///< sd
  Eigen::Vector3d mag_dist_world_ut{0, 0, 0};      ///< ENU
  double mag_dist_norm_ut = 0.0;
  Eigen::Vector3d gyro_bias_rps{0, 0, 0};
  double gyro_bias_sigma_rps = 0.0;  ///< standard deviation of the least known bias component, rad/s
  bool rest = false;              ///< rest detected (bias estimation)
  bool mag_used = false;          ///< the last magnetometer sample corrected the heading
  bool field_learnt = false;      ///< m and alpha known (configured or learnt)
  double field_magnitude_ut = 0;  ///< m
  double dip_rad = 0;             ///< alpha
};

/// The published attitude covariance term by term (rad^2, world rotation vector, as
/// ParallelKf::attitude_covariance): what each modelled error contributes, so each one's share can
/// be measured against the real error. The covariance is their sum.
struct ParallelKfCovarianceTerms {
  Eigen::Matrix3d kf = Eigen::Matrix3d::Zero();              ///< the two KFs' own covariances
  Eigen::Matrix3d bias_lag = Eigen::Matrix3d::Zero();        ///< the attitude error the bias error left
  Eigen::Matrix3d external_accel = Eigen::Matrix3d::Zero();  ///< external acceleration in the low-passed vector
  Eigen::Matrix3d gyro_scale = Eigen::Matrix3d::Zero();      ///< a gyro scale error (gyro_scale_error)
  Eigen::Matrix3d field = Eigen::Matrix3d::Zero();           ///< the disturbance of the fields used
  Eigen::Matrix3d delay = Eigen::Matrix3d::Zero();           ///< the output's prediction over an unknown delay
  Eigen::Matrix3d hard_iron = Eigen::Matrix3d::Zero();       ///< the removed hard-iron offset's error
  Eigen::Matrix3d unknown_heading = Eigen::Matrix3d::Zero(); ///< a heading nothing bounds
  [[nodiscard]] Eigen::Matrix3d sum() const {
    return kf + bias_lag + external_accel + gyro_scale + field + delay + hard_iron + unknown_heading;
  }
};

/// Everything the parallel KF carries from one sample to the next (besides its parameters):
/// inspect it, save it, restore it into a filter with the same parameters (`set_state`). Nothing
/// that evolves with the samples lives outside it: the output attitude and the per-source reports
/// are here too, so a restored state gives the same outputs and reports bit for bit.
struct ParallelKfState {
  /// What the last sample's heading step did with s_M (for the mag report).
  /// kPending: the reading carries a hard-iron offset not yet known well enough to remove
  /// (HardIronEstimator::pending): not used, and the gate not asked.
  /// kMovedAtRest: the field turned in the (gyro-propagated) inertial frame while the sensor was
  /// at rest (field_moved_at_rest): not used, and the gate not asked.
  enum class MagUse : uint8_t { kNone, kLearning, kGated, kForced, kRestarted, kPending, kMovedAtRest };

  TiltKf kf1;
  DirectionKf kf2;
  bool initialized = false;
  bool heading_initialized = false;
  /// 6-axis: KF2 holds north at the start's yaw 0 propagated by the gyro, not a field direction
  bool heading_from_gyro = false;
  int64_t last_stamp_ns = -1;
  Eigen::Vector3d prev_gyro{0, 0, 0};  ///< bias-corrected s_G at k-1
  Eigen::Vector3d prev2_gyro{0, 0, 0};  ///< bias-corrected s_G at k-2 (quadratic_rate)
  double prev_dt_s = 0.0;  ///< the interval between k-2 and k-1, s (0: no sample k-2)
  RejectCounters rejections;
  bool mag_used = false;  ///< the last magnetometer sample corrected the heading
  /// q_world_body (ENU) from sZ and sX' (2) after the last accepted sample: computed once per
  /// update; the last valid one while they are (anti)parallel, identity before the first sample.
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();

  FieldGate gate;  ///< magnetic field reference, gate, re-acquisition (poise/core/field_gate.h)
  double mag_extra_var = 0.0;  ///< soft-gating inflation of M2 for the current sample, uT^2
  double mag_adapt_var = 0.0;  ///< the disturbance noise added to M2 for the last accepted field (mag_adaptive_noise), uT^2

  // inertial low-pass of the accelerometer
  /// body -> almost inertial frame, gyro only (accel_lowpass_tau_s > 0 or hard_iron)
  Eigen::Matrix3d r_ib = Eigen::Matrix3d::Identity();
  int r_ib_steps = 0;
  Eigen::Vector3d lp_accel_i{0, 0, 0};
  Butterworth2<3> accel_bw;
  Eigen::Vector3d last_accel{0, 0, 0};

  // bias / rest
  Eigen::Vector3d bias{0, 0, 0};
  Eigen::Matrix3d bias_cov = Eigen::Matrix3d::Zero();  ///< covariance of the bias estimate, rad^2/s^2
  /// covariance of the bias estimate's error: the gains of bias_cov's filter, with the noise its
  /// measurements really have (bias_cov's is larger by design; motion_noise_window), rad^2/s^2
  Eigen::Matrix3d bias_err_cov = Eigen::Matrix3d::Zero();
  /// cross-covariance of the bias estimate's real error (body) with the attitude error of the
  /// estimate that is not the bias's (world rotation vector: what the motion measurements' noise
  /// is the rate of; motion_noise_window), rad^2/s
  Eigen::Matrix3d bias_err_att_cov = Eigen::Matrix3d::Zero();
  Eigen::Vector3d bias_lp_i{0, 0, 0};  ///< the bias in the inertial frame, low-passed as the accelerometer
  double rate2_lp = 0.0;    ///< |s_G|^2 low-passed over rest_filter_tau_s (without the accelerometer low-pass), rad^2/s^2
  // motion bias window (summed between updates)
  Eigen::Vector3d mb_corr{0, 0, 0};  ///< KF1's correction rotations, rad (body)
  double mb_rate2 = 0.0;             ///< integral of |s_G|^2 dt, rad^2/s (without the accelerometer low-pass)
  Eigen::Vector3d mb_rate_i{0, 0, 0};  ///< integral of R_ib s_G dt (almost inertial frame; with the low-pass), rad
  Eigen::Vector3d rate_lp_i{0, 0, 0};  ///< R_ib s_G low-passed over accel_lowpass_tau_s, rad/s
  double mb_head = 0.0;              ///< KF2's heading corrections about sZ / cos^2(dip), rad
  double mb_time = 0.0;              ///< s
  bool mb_head_used = false;         ///< an accepted magnetometer update in the window
  bool mb_head_trusted = true;       ///< no gated or forced magnetometer sample in the window
  double c2_dip = 1.0;               ///< max(cos^2(alpha), guard), for alpha = c2_dip_for
  double c2_dip_for = 0.0;
  RestDetector rest_det;
  StampAnchor anchor;  ///< time restarts after a stamp jump only when two samples agree
  StateHealth health;  ///< resets after an unhealthy update (poise/core/state_health.h)

  // What the last sample did with each input (parallel_kf_report.cpp turns it into sources()).
  MagUse mag_use = MagUse::kNone;
  double gate_norm_ut = std::nan("");  ///< |s_M| at the gate (NaN: not gated this sample)
  double gate_sin_dip = 0.0;           ///< sin(dip) at the gate
  SourceReport gyro_src = SourceReport(Source::kGyro);
  SourceReport accel_src = SourceReport(Source::kAccel);
  SourceReport mag_src = SourceReport(Source::kMag);

  /// The hard-iron offset estimate (hard_iron); fed every accepted sample with a magnetometer
  HardIronEstimator hard_iron;
  bool mag_corrected = false;  ///< the last sample's s_M had the hard-iron offset removed
  bool mag_offset_pending = false;  ///< the last sample's s_M carried an offset that cannot be removed yet
  /// r_ib s_M low-passed over rest_filter_tau_s, and its value when the current rest began (NaN:
  /// not at rest), uT: the field seen from the gyro's almost inertial frame (field_moved_at_rest)
  FieldMovedAtRest rest_field;
  bool mag_moved_at_rest = false;  ///< the last sample's field had moved since the rest began (or is held)
  /// The turn about the vertical (rad, body sZ) KF2's accepted fields gave the heading at rest since
  /// the last reading that was within the gate's norm tolerance of the rest's field: taken back
  /// when the field is found to have moved (field_moved_at_rest).
  double rest_heading_turn_rad = 0.0;
  uint64_t rest_turns_reverted = 0;  ///< fields found moved at rest whose heading turns were taken back
  /// continuous time the field was refused before the gate (moved at rest, offset pending) since
  /// the gate last used one, s: with the gate's own rejected time, what heading_status() counts
  double field_refused_s = 0.0;
  uint64_t mag_corrected_count = 0;  ///< samples whose s_M had the offset removed

  // What the two KFs do not model, for the published covariance (attitude_covariance)
  double accel_dev2_lp = 0.0;  ///< without the low-pass: (|s_A| - g)^2, low-passed over rest_filter_tau_s, (m/s^2)^2
  /// The gravity reference: the accelerometer in the almost inertial frame through three
  /// first-order stages of kAccelReferenceTaus / 3 tilt low-pass time constants each (columns 0-2,
  /// m/s^2), combined as (1 + b s) / (1 + T s)^3 with b = 3 T - tau (external_accel_step): a ramp
  /// lags it by tau, as it lags the tilt's low-pass, while an acceleration passes it as b / T^3
  /// over s^2, not as 1 / T over s (a first-order reference)
  Eigen::Matrix3d accel_ref_stages_i = Eigen::Matrix3d::Zero();
  /// the low-passed accelerometer's deviation from the reference across it (the horizontal external
  /// acceleration the tilt's low-pass let through), its outer product low-passed over
  /// accel_lowpass_tau_s, inertial frame, (m/s^2)^2
  Eigen::Matrix3d accel_h_cov_i = Eigen::Matrix3d::Zero();
  /// that deviation itself low-passed over KF2's lag (inertial frame, m/s^2): its part about magnetic
  /// north is what KF2 pulls the heading with (-tan(dip) times the tilt)
  Eigen::Vector3d accel_h_heading_i{0, 0, 0};
  /// the deviation times that low-passed one (d accel_h_heading_i^T), low-passed over
  /// accel_lowpass_tau_s as accel_h_cov_i (inertial frame, (m/s^2)^2): the tilt's and the heading's
  /// shares of the acceleration come from one realisation, and this is their cross moment
  Eigen::Matrix3d accel_h_cross_i = Eigen::Matrix3d::Zero();
  /// The tilt's low-pass run again on the same input (accel_bw's twin), for the external
  /// acceleration term only: it and the reference are turned by each bias change into the frame the
  /// new bias would have propagated (external_accel_return), so their difference holds no turn of
  /// the frame by past bias errors (the estimate's own lag error from them is lag_cov's)
  Butterworth2<3> accel_bw_twin;
  /// Per low-pass (the twin, with the tilt's time constant; each reference stage): the sum over its
  /// samples of weight times the integral of r_ib from the sample to now, s: a bias change db turns
  /// the low-passed vector y by (this db) x y
  Eigen::Matrix3d accel_twin_age = Eigen::Matrix3d::Zero();
  std::array<Eigen::Matrix3d, 3> accel_ref_stage_age{Eigen::Matrix3d::Zero(), Eigen::Matrix3d::Zero(),
                                                     Eigen::Matrix3d::Zero()};
  Eigen::Vector3d accel_ref_i{0, 0, 0};      ///< the reference, L3 + c (L2 - L3) (reference_step), m/s^2
  double accel_ref_c = 0.0;                   ///< its c, for a ramp lag of tau
  double accel_ref_g_ratio = 0.0;             ///< what it lets through of an acceleration, in phase, over the twin's
  Eigen::Vector3d accel_ref_sum_i{0, 0, 0};   ///< the accelerometer's integral over the bias period so far, m/s
  double accel_ref_sum_s = 0.0;               ///< that period so far, s
  Eigen::Vector3d accel_ref_stage_lag{0, 0, 0};  ///< each reference stage's ramp lag (its weights' mean age), s
  double accel_ref_span_s = 0.0;  ///< time the reference has averaged (its stages' window until their time constant), s
  double field_dn_lp = 0.0;    ///< |s_M| - m of the fields used for heading, low-passed over KF2's lag, uT
  double field_dv_lp = 0.0;    ///< m (dip - alpha) of the same, low-passed the same way, uT
  /// the bias period's integrals of the accepted fields' norm (uT s) and sine of dip (s), and
  /// their span (s), on which field_dn_lp / field_dv_lp step
  double field_dev_norm_sum = 0.0;
  double field_dev_sin_dip_sum = 0.0;
  double field_dev_span_s = 0.0;
  /// KF2's innovations about the vertical (field_rotation_step), rad: their horizontal angle from
  /// the prior direction low-passed over KF2's lag (nu_lp), its square low-passed the same way
  /// (nu2_lp, rad^2), and what the model expects of that square (the white noise's and the bias
  /// error's, nu_model, rad^2)
  double field_nu_lp = 0.0;
  double field_nu2_lp = 0.0;
  double field_nu_model = 0.0;
  double field_model_lp = 0.0;   ///< field_heading_var low-passed over KF2's lag, rad^2
  double field_model_lp2 = 0.0;  ///< that low-passed again (nu_model's share of it), rad^2
  /// v^T P v, P the published covariance but field_rotation_var, v = up + tan(dip) magnetic north
  /// (world): what field_rotation_step expects of its innovation, rad^2; taken with field_dip_tilt_var
  double field_heading_var = 0.0;
  /// alpha for field_dv_lp with a learnt reference: the accepted dips' mean weighted by the inverse
  /// published tilt variance about magnetic east (field_dip_reference), rad; NaN = not started
  double field_dip_ref = std::nan("");
  double field_dip_weight = 0.0;  ///< its sum of weights, s/rad^2
  uint64_t field_dip_epoch = 0;   ///< the gate's reference_epoch when it started
  /// the published tilt variance about magnetic east those weights use, rad^2 (NaN = not taken
  /// yet), and the time since it was taken, s: refreshed once per bias window
  double field_dip_tilt_var = std::nan("");
  double field_dip_var_age_s = 0.0;
  /// The attitude error the bias error has left in the estimate (world frame x, y, z, rad; then
  /// the second state of the tilt low-pass's error about x and y, rad/s, for a second-order
  /// low-pass): it drifts by R (b_true - b), the tilt forgets the drift through the accelerometer
  /// low-pass, the heading with KF2's lag (only while fields are accepted). Its covariance, and its
  /// cross-covariance with the bias error (x body), are propagated once per bias window and
  /// updated with every bias measurement, so an error left by a bias that has since been learnt
  /// stays until the lags have forgotten it.
  Eigen::Matrix<double, 5, 5> lag_cov = Eigen::Matrix<double, 5, 5>::Zero();
  Eigen::Matrix<double, 5, 3> lag_bias_cov = Eigen::Matrix<double, 5, 3>::Zero();
  double since_mag_s = 0.0;    ///< time since fields last held the heading (each accepted one removes dt / KF2's lag of it), s
  double lag_keep_z = 1.0;  ///< share of the heading's lag error left by the accepted fields of the bias window
  double last_dt_s = 0.0;      ///< the last step, s
  /// KF2's direction was (re)started from a field the gate did not gate (learning, accepted or
  /// relearnt); false after a start on a gated field (a configured reference next to a magnet):
  /// the first accepted field then restarts it
  bool heading_anchored = false;
  /// body -> an inertial frame by the gyro alone (integrated here only when r_ib is not kept:
  /// ParallelKf::gyro_attitude()), and that attitude low-passed as the tilt (accel_lowpass_tau_s)
  /// and the heading (KF2's lag) follow it (gyro scale error), stepped once per bias period
  Eigen::Quaterniond q_ib = Eigen::Quaterniond::Identity();
  Eigen::Quaterniond q_lp_tilt = Eigen::Quaterniond::Identity();
  Eigen::Quaterniond q_lp_heading = Eigen::Quaterniond::Identity();
  double scale_lp_s = 0.0;  ///< time since the two low-passes last stepped (once per bias period), s
};

class ParallelKf {
 public:
  explicit ParallelKf(const ParallelKfParams& params = {});

  /// One sample. Returns false when the sample was rejected (counted in rejections()); a sample
  /// with a bad magnetometer but good gyro/accelerometer is used without its magnetometer. Also
  /// false when the update left the state non-finite or a covariance not one: the filter is then
  /// reset (counters kept), counted in state_resets() and starts again from the next sample.
  bool update(const ImuSample& s);
  /// Back to the state of a new filter (parameters kept).
  void reset();
  /// The filter's whole state (VQF's getState): two filters with the same parameters and the
  /// same state give the same outputs for the same samples.
  [[nodiscard]] const ParallelKfState& state() const { return s_; }
  /// The heading variance the field's horizontal rotation adds (field_rotation_step): twice what
  /// KF2's low-passed innovations about the vertical show beyond the model, rad^2 (in the field term).
  [[nodiscard]] double field_rotation_var() const;
  /// Restores a state taken from state() of a filter with the same parameters (setState).
  void set_state(const ParallelKfState& state) { s_ = state; }

  [[nodiscard]] bool initialized() const { return s_.initialized; }
  /// Everything reported (computed on demand from the state).
  [[nodiscard]] ParallelKfOutput output() const;
  /// The published attitude covariance of output(): attitude_covariance(output()) without the
  /// rest of output() (its Euler angles, norms and rotations: covariance_terms reads only the
  /// attitude and the dip).
  [[nodiscard]] Eigen::Matrix3d attitude_covariance() const { return attitude_covariance(covariance_output()); }
  /// Covariance of the world-frame attitude error (rad^2, rotation vector about ENU x, y, z) of
  /// `out` (= output()), the one the filter publishes: the two KFs' own covariances (tilt from the
  /// up vector's, heading from the horizontal part of the field direction's over cos(dip)^2) plus
  /// what they do not model (docs/ESTIMATORS.md "The published covariance"):
  ///   all     + the attitude error left by the bias error (lag_cov): it drifts the estimate by
  ///             R b; the tilt forgets that drift with the accelerometer low-pass's lag tau (a
  ///             ramp b gives tau b), the heading with KF2's lag while fields are accepted, not
  ///             while they are gated. Propagated with the bias error's cross-covariance, so the
  ///             error a bias left before it was learnt is forgotten with the lags, not at once;
  ///           + the horizontal external acceleration a_h the low-pass let through, tilting the
  ///             estimate by e_z x a_h / g: the low-passed vector's part across a slow gravity
  ///             reference (the accelerometer in the almost inertial frame through three stages of
  ///             kAccelReferenceTaus tau / 3, combined so that a ramp lags it by tau as it lags the
  ///             tilt's low-pass: the present bias error's steady turn cancels; reference_step; both
  ///             it and the low-passed vector, a twin of the tilt's, turned by each bias change into
  ///             the frame the new bias would have propagated, so the turn of the frame by past bias
  ///             errors is not read as an acceleration: that error of the estimate is lag_cov's),
  ///             divided by 1 - G_ref / G_twin (what the reference lets through of a fast
  ///             acceleration, in phase with the twin), its outer product low-passed over tau
  ///             (external_accel_step); a vertical acceleration, which only changes the magnitude,
  ///             does not count (without the low-pass: (|s_A| - g)^2 / g^2 per tilt axis, as
  ///             before); heading: tan^2(dip) times its tilt about magnetic north low-passed over
  ///             KF2's lag, to which KF2 pulls the heading;
  ///           + s^2 dtheta_i^2 about each body axis i (world x, y part): a gyro scale error s
  ///             (gyro_scale_error, the sensor's; not known: motion_gyro_scale_error) turns the
  ///             attitude by s times the rotation dtheta away
  ///             from the attitude low-passed over tau, which the tilt has not caught up with;
  ///             each accepted field removes the share dt / tau_2 of the heading's (tau_2 KF2's
  ///             lag about the vertical), so a field accepted now and then amid gated ones leaves
  ///             most of a gated stretch's drift in it; and KF2 pulls the heading towards
  ///             -tan(dip) times the tilt error about magnetic north (the heading is built from sZ);
  ///           (P_b here is bias_err_cov, the covariance of the bias estimate's real error: the
  ///             bias filter's gains with the noise its measurements really have, not the larger
  ///             one the filter is designed with: the gyro's white noise over the window
  ///             (gyro_noise_density_rps_per_sqrt_hz when the sensor says it) and, in motion, the
  ///             rate of the estimate's own attitude error, the bias's lag error's included
  ///             (motion_noise_window, LagIncrement); growing by the gyro's own bias walk
  ///             gyro_bias_walk_rps_per_sqrt_s when the sensor says it)
  ///           each diagonal term at least tau^2 P_b (tilt) and P_b,z t^2 (heading; t the time
  ///             since fields last held the heading, each accepted field removing dt / tau_2 of
  ///             it): the bias filter's motion measurements are the lag error's own rate, so its
  ///             P_b decorrelates from that error faster than the error does;
  ///           + the scale error's part about the vertical, with the attitude low-passed over tau_2;
  ///           + the disturbance of the fields used, averaged over KF2's lag (the norm and dip
  ///             deviations from the reference, low-passed; the dip's against the accepted dips' mean weighted
  ///             by the inverse tilt variance about magnetic east, field_dip_reference), over (m cos(dip))^2: its horizontal
  ///             part across the field, which moves the heading, is taken as large as the two the
  ///             gate can see (the mean of their squares);
  ///           + a horizontal rotation of the field, which the gate cannot see (field_rotation_var):
  ///             twice KF2's innovation about the vertical low-passed over its lag, squared and
  ///             low-passed again, less what the rest of the covariance explains of it;
  ///   both    + (dt^2 / 12) (R w)(R w)^T while imu_delay_s is not known (NaN): the output is
  ///             predicted over half a sample, the true delay taken as uniform over none to one
  ///             sample; its error turns the attitude about the rate axis w;
  ///   heading + x^T P_hi x / (m cos(dip))^2 while the hard-iron offset is removed (hard_iron): its
  ///             estimate's error (covariance P_hi, body, uT^2) stays in every reading; its horizontal
  ///             part across the field (x, body: up x sX' normalised) turns the heading by
  ///             e.x / B_h, and a constant error is not averaged out by KF2's lag;
  ///   heading + pi^2 / 3 (a heading uniform over +-180 deg) while the field reference is not
  ///             verified or the heading was started on a gated field: nothing bounds it then.
  /// Not coupled between tilt and heading (the two KFs are independent by design).
  [[nodiscard]] Eigen::Matrix3d attitude_covariance(const ParallelKfOutput& out) const;
  /// attitude_covariance(out), term by term (their sum is it).
  [[nodiscard]] ParallelKfCovarianceTerms covariance_terms(const ParallelKfOutput& out) const;
  /// Whether the heading is backed by a trusted field (poise/core/heading_status.h):
  /// kNoReference before a field (6-axis: the gyro's heading); kVerified when the field reference
  /// is verified (configured, or accepted for mag_verify_s), the heading was started or corrected
  /// by a field the gate did not gate, and the gate has not rejected the field for mag_verify_s;
  /// kUnverified otherwise (learning, a provisional reference, a long gated stretch).
  [[nodiscard]] HeadingStatus heading_status() const;
  /// True while nothing bounds the heading (a provisional field reference, or KF2 started on a
  /// field the gate gated): attitude_covariance() then adds pi^2 / 3 to the heading variance.
  [[nodiscard]] bool heading_unknown() const;
  /// q_world_body (ENU) from sZ and sX' (2) after the last accepted sample (the state's); the
  /// last valid one if they are (anti)parallel.
  [[nodiscard]] Eigen::Quaterniond q_world_body() const { return s_.q_world_body; }
  [[nodiscard]] Eigen::Matrix<double, 6, 6> tilt_covariance() const { return s_.kf1.covariance(); }
  [[nodiscard]] Eigen::Matrix<double, 6, 6> heading_covariance() const { return s_.kf2.covariance(); }
  [[nodiscard]] const TiltKf& tilt_kf() const { return s_.kf1; }
  [[nodiscard]] const RejectCounters& rejections() const { return s_.rejections; }
  /// Magnetometer samples not used for the heading: gated as disturbed.
  [[nodiscard]] uint64_t mag_gated_count() const { return s_.gate.gated; }
  [[nodiscard]] uint64_t field_reacquired_count() const { return s_.gate.reacquired; }
  /// Provisional (not yet verified) references replaced by a consistent field (mag_verify_s).
  [[nodiscard]] uint64_t field_relearnt_count() const { return s_.gate.relearnt; }
  /// Start-up references moved by a hard-iron offset that was there at start-up (a magnet on the
  /// sensor at power-on; FieldGate::offset_removed).
  [[nodiscard]] uint64_t field_offset_moves_count() const { return s_.gate.offset_moves; }
  /// Magnetometer samples used although gated, because rejection lasted mag_max_reject_s.
  [[nodiscard]] uint64_t mag_forced_count() const { return s_.gate.forced; }
  /// Magnetometer samples whose reading had the hard-iron offset removed (hard_iron).
  [[nodiscard]] uint64_t mag_hard_iron_corrected_count() const { return s_.mag_corrected_count; }
  /// Fields found moved at rest whose heading turn since the reading last agreed with the rest's
  /// field was taken back (field_moved_at_rest).
  [[nodiscard]] uint64_t rest_turns_reverted_count() const { return s_.rest_turns_reverted; }
  [[nodiscard]] const HardIronEstimator& hard_iron() const { return s_.hard_iron; }
  /// Resets after an unhealthy state (poise/core/state_health.h).
  [[nodiscard]] uint64_t state_resets() const { return s_.health.resets; }
  [[nodiscard]] const ParallelKfParams& params() const { return p_; }
  /// Sets imu_delay_s (e.g. the delay the IMU's driver publishes), any time: only the output's
  /// prediction over the delay uses it, from the next update on. Throws std::invalid_argument
  /// outside [0, 0.05] s (the range validate() checks); NaN = not known (half a sample).
  void set_imu_delay_s(double delay_s);
  /// Per source for the last sample (parallel_kf_report.cpp), in this order:
  ///   gyro   fused when it propagated both KFs (not available on the first sample / after a gap);
  ///   accel  KF1's correction: innovation s_A - H1 x1 (m/s^2; of the low-passed accelerometer when
  ///          accel_lowpass_tau_s > 0), variance diag(H1 P1 H1^T) + sigma_A^2 with P1 after the
  ///          update (the filter keeps no prior), never gated;
  ///   mag    KF2's heading update: innovation [|s_M| - m (uT), dip - alpha (rad)], variance the
  ///          squared gate tolerances, so test ratio > 1 <=> outside the gate; fused
  ///          "hard_iron_corrected" when the reading had the hard-iron offset removed. Rejected
  ///          "disturbed" (gated), fused "forced_after_max_reject" (used although gated, after
  ///          mag_max_reject_s), not available "learning_field" / "no_sample" /
  ///          "use_magnetometer_false", rejected with the sample check's reason (non_finite_mag,
  ///          zero_mag) or the whole sample's (no_magnetometer with use_magnetometer: true).
  /// Innovations and test ratios are computed here, on demand (update() only records decisions).
  [[nodiscard]] SourceReports sources() const;

 private:
  /// What a window's motion measurements really carry besides the bias (bias_error_update): the
  /// gyro's white noise averaged over the window, and the rate of the attitude error x that is not
  /// the bias's over it, -(x_j - x_{j-1}) / t. x (world rotation vector) is taken as first-order
  /// Gauss-Markov per axis: its covariance the published terms that are not the bias's
  /// (reference_error_cov), its time constant the lag of the KF that follows it (the
  /// accelerometer low-pass's tau for the tilt, KF2's for the heading). d and its moments also
  /// carry the bias's own lag error's increment (LagIncrement, independent of x): the correction
  /// rate a window measures is the rate of the whole error, whose lag part follows the bias error
  /// itself (at a start the correction has not yet turned, and the window tells little of b).
  struct MotionNoise {
    Eigen::Matrix3d e_d = Eigen::Matrix3d::Zero();   ///< E[b_err d^T], d = x_j - x_{j-1}, body x world
    Eigen::Matrix3d e_x = Eigen::Matrix3d::Zero();   ///< E[b_err x_j^T], body x world
    Eigen::Matrix3d d_d = Eigen::Matrix3d::Zero();   ///< E[d d^T], world
    Eigen::Matrix3d d_x = Eigen::Matrix3d::Zero();   ///< E[d x_j^T], world
    Eigen::Matrix3d r = Eigen::Matrix3d::Identity();  ///< R_world_body
    double t = 0.0;                                   ///< the window, s
    /// E[x_lag,j d^T] (5 x world): the lag error (lag_cov) against the window's increment
    Eigen::Matrix<double, 5, 3> lag_x_d = Eigen::Matrix<double, 5, 3>::Zero();
  };
  /// The bias's own lag error's increment over the window just propagated, d = x_j - x_{j-1}
  /// (lag_cov's world x, y, z): a motion measurement is the rate of the estimate's whole attitude
  /// error, so it carries this too (propagate_lag_error computes it, motion_noise_window adds it).
  struct LagIncrement {
    Eigen::Matrix3d d_d = Eigen::Matrix3d::Zero();  ///< E[d d^T], world
    Eigen::Matrix3d b_d = Eigen::Matrix3d::Zero();  ///< E[b_err d^T], body x world
    Eigen::Matrix<double, 5, 3> x_d = Eigen::Matrix<double, 5, 3>::Zero();  ///< E[x_j d^T]
  };
  bool step(const ImuSample& s, SampleCheck& c);  ///< update() without the reporting
  void initialize(const ImuSample& s, bool mag_ok);
  /// Feeds the hard-iron estimate (hard_iron, a sample with a usable s_M: `gyro` bias-corrected,
  /// `mag` raw, with s_.r_ib: the rotation between its readings comes from this filter's
  /// transitions, not a second gyro integration) and returns the reading the gate and KF2 see:
  /// `mag` less the offset while it is applied (s_.mag_corrected), `mag` otherwise
  Eigen::Vector3d hard_iron_corrected(int64_t stamp_ns, const Eigen::Vector3d& gyro, const Eigen::Vector3d& mag,
                                      bool mag_ok);
  /// The rate over the step of dt to the bias-corrected `gyro`: w its mean (the previous and current
  /// rates weighted by gyro_current_weight; with quadratic_rate, the mean of the quadratic through
  /// k-2, k-1, k) and, with the coning term, the coning rotation (rad) of that rate over the step
  struct StepRate {
    Eigen::Vector3d w;
    Eigen::Vector3d coning;
  };
  [[nodiscard]] StepRate step_rate(const Eigen::Vector3d& gyro, double dt) const;
  /// The step's transition for both filters, from the step rate (step_rate)
  [[nodiscard]] Eigen::Matrix3d transition(const StepRate& r, double dt) const;
  void bias_update();  ///< the bias filter over the window s_.mb_time (predict, rest or motion)
  /// One scalar bias measurement along unit h (body): value z (rad/s), noise variance w; the
  /// component along unit *keep (if given) is left as it is; `mn` (a motion measurement's window,
  /// else null) for the real error's update (bias_error_update).
  void bias_measure(const Eigen::Vector3d& h, double z, double w, const Eigen::Vector3d* keep, MotionNoise* mn);
  void motion_bias_measure(const LagIncrement& lag);
  /// The horizontal external acceleration the tilt's low-pass let through (accel_h_cov_i), from
  /// the raw accelerometer in the almost inertial frame `accel_i` (r_ib times the body's, which
  /// step() computes once for the tilt's low-pass) of a step of dt; for the covariance. The twin
  /// steps every sample, the reference, the twin's age and the moments once per bias period.
  void external_accel_step(const Eigen::Vector3d& accel_i, double dt);
  /// Steps the gravity reference (accel_ref_i, its stages, ages and lags) over the bias period on
  /// the period's mean of the accelerometer in the almost inertial frame.
  void reference_step();
  /// The gyro-only attitude and its two low-passes (the gyro scale error's covariance term).
  void scale_error_step(const Eigen::Vector3d& w, double dt);
  /// Whether step() keeps the gyro-only frame r_ib (the accelerometer low-pass or the hard-iron estimate).
  [[nodiscard]] bool gyro_frame_kept() const;
  /// The gyro-only attitude: r_ib where it is kept, else q_ib.
  [[nodiscard]] Eigen::Quaterniond gyro_attitude() const;
  /// While the hard-iron offset is removed (mag_corrected): the variance of its estimate's error
  /// across the field, x^T P_b x with x the unit horizontal direction across the field (body: up x
  /// sX' normalised), uT^2; the part of the error that turns the heading. 0 otherwise.
  [[nodiscard]] double removed_offset_var_across_ut2() const;
  /// At rest: adds the turn about the vertical KF2's last correction (from x_prior) gave the heading
  /// to rest_heading_turn_rad.
  void add_rest_heading_turn(const Eigen::Vector3d& x_prior);
  /// Turns the twin low-pass and the gravity reference of external_accel_step by a bias change
  /// db (body, rad/s): the frame the new bias would have propagated, the vectors' samples turned
  /// by the integral of r_ib db from each sample to now (accel_twin_age, accel_ref_stage_age).
  void external_accel_return(const Eigen::Vector3d& db);
  [[nodiscard]] double motion_bias_noise(double dt) const;
  /// The gyro's scale error the published covariance takes: gyro_scale_error, or not known
  /// (NaN), motion_gyro_scale_error
  [[nodiscard]] double gyro_scale_error() const;
  /// KF2's correction lag about the vertical for a step of dt, s (0 before a direction exists)
  [[nodiscard]] double heading_lag_s(double dt) const;
  /// Propagates the attitude error the bias error leaves (lag_cov, lag_bias_cov) over t seconds.
  /// Returns the lag error's increment over the window (LagIncrement).
  LagIncrement propagate_lag_error(double t);
  /// x's statistics over a window of t seconds, with the bias's lag error's increment `lag` added
  [[nodiscard]] MotionNoise motion_noise_window(double t, const LagIncrement& lag) const;
  /// x's decay over a window of t seconds per world axis, e^(-t / tau) (motion_noise_window's A).
  [[nodiscard]] Eigen::Vector3d reference_error_decay(double t) const;
  /// The covariance of the estimate's attitude error that is not the bias's (world, rad^2): the
  /// published terms but the bias lag, the output's delay and an unknown heading, the heading's
  /// part also carrying -tan(dip) times the tilt error about magnetic north (KF2 pulls it there).
  [[nodiscard]] Eigen::Matrix3d reference_error_cov() const;
  /// The white gyro noise of the mean of a window of t seconds, (rad/s)^2: the sensor's density
  /// gyro_noise_density_rps_per_sqrt_hz squared over t, or not known, KF2's sigma_G per sample.
  [[nodiscard]] double gyro_white_var(double t) const;
  /// The bias estimate's real error variance per axis at start, (rad/s)^2: the sensor's
  /// gyro_initial_bias_sd_rps squared, or not known, the design's bias_sigma_init_rps squared.
  [[nodiscard]] double initial_bias_err_var() const;
  /// bias_err_cov (and bias_err_att_cov) after a bias measurement along h with gain k, whose
  /// noise is white of variance w_white plus, with `mn`, the window's attitude error rate.
  void bias_error_update(const Eigen::Vector3d& h, const Eigen::Vector3d& k, double w_white, MotionNoise* mn);
  /// Whether the raw field `mag` has moved, in the gyro's almost inertial frame,
  /// by more than the gate's norm tolerance since the current rest began (false when not at rest)
  bool field_moved_at_rest(const Eigen::Vector3d& mag, bool mag_ok, double dt);
  /// KF2's correction (predicted already, before KF1's correction was shared) and the gate
  void heading_step(const Eigen::Vector3d& mag, bool mag_ok, double dt);
  /// M2's inflation for an accepted field: soft gating, the removed offset's error, the disturbance
  /// KF2's innovation shows (mag_adaptive_noise)
  void field_noise_step();
  /// KF2 restarted on the field `mag` (a relearnt reference, or the first accepted field after a
  /// start on a gated one): the heading jumps to it, as at a start
  void restart_heading(const Eigen::Vector3d& mag);
  /// field_dn_lp / field_dv_lp from an accepted field, after KF2's correction (lag: KF2's, s)
  void field_deviation_step(const Eigen::Vector3d& mag, double lag, double dt);
  /// field_nu_lp / field_nu2_lp / field_nu_model from an accepted field: its horizontal angle from
  /// KF2's prior direction `x_prior` about sZ (the innovation's; lag: KF2's, s)
  void field_rotation_step(const Eigen::Vector3d& mag, const Eigen::Vector3d& x_prior, double lag, double dt);
  /// The dip the field term measures dv against (updated with the accepted dip `dip`), rad
  double field_dip_reference(double dip, double dt);
  /// field_dip_tilt_var and field_heading_var from the published covariance, once per bias window
  /// of accepted fields (and at once when not taken yet)
  void field_variances_step(double dt);
  /// The external acceleration's term of covariance_terms (world axes; r = R_world_body): the tilt
  /// the low-pass let through, the heading KF2 takes from it, and their cross-covariance
  [[nodiscard]] Eigen::Matrix3d external_accel_covariance(const Eigen::Matrix3d& r) const;

  /// covariance_terms(out) with the bias_lag and delay terms left zero unless `lag_and_delay`
  /// (reference_error_cov does not read them)
  [[nodiscard]] ParallelKfCovarianceTerms covariance_terms(const ParallelKfOutput& out, bool lag_and_delay) const;
  /// output()'s attitude and dip, the only fields covariance_terms reads (the rest left default)
  [[nodiscard]] ParallelKfOutput covariance_output() const;
  /// The delay the output is predicted over, s: imu_delay_s, or half the last step when not known.
  [[nodiscard]] double output_delay_s() const;
  /// s_.q_world_body from sZ and sX' (2), predicted over output_delay_s(); kept when they are
  /// (anti)parallel or sZ is not a direction.
  void update_attitude();

  ParallelKfParams p_;
  FieldGateParams gp_;          ///< p_.field_gate(), built once
  DirectionKfParams kf2_params_;  ///< KF2's, from p_, built once
  // propagate_lag_error()'s transition over a window of lag_t_ s (a function of t and p_ only)
  double lag_t_ = -1.0;
  Eigen::Matrix<double, 5, 5> lag_phi_ = Eigen::Matrix<double, 5, 5>::Identity();
  Eigen::Matrix<double, 5, 3> lag_gam_b_ = Eigen::Matrix<double, 5, 3>::Zero();
  // Values of slowly changing inputs, kept with the input they are for (a pure function of it:
  // the same as computing it each time)
  mutable double tan_dip_for_ = std::nan("");  // tan_dip_: guarded_tan_dip() for this dip
  mutable double tan_dip_ = 0.0;
  mutable double cos_dip_for_ = std::nan("");  // cos_dip_: max(cos(dip), 0.1) (covariance_terms) for this dip
  mutable double cos_dip_ = 0.0;
  double dip_forget_dt_ = std::nan("");  // dip_forget_: field_dip_reference's exp(-dt / tau) for this dt
  double dip_forget_ = 1.0;
  /// tan(dip) with cos(dip) held at sqrt(kMinCos2Dip) or more
  [[nodiscard]] double guarded_tan_dip() const;
  ParallelKfState s_;

  // Reporting (parallel_kf_report.cpp): the state's per-source reports of the last sample.
  void report(const ImuSample& s, const SampleCheck& c, bool accepted, bool was_initialized);
  [[nodiscard]] bool healthy();  ///< the state health check (state_health.h)
  void reset_unhealthy();        ///< reset() keeping the counters and reports, one reset counted
};

/// AttitudeFilter adapter.
class ParallelKfFilter : public AttitudeFilter {
 public:
  explicit ParallelKfFilter(const ParallelKfParams& p = {}) : kf_(p), delay_configured_(!std::isnan(p.imu_delay_s)) {}
  bool update(const ImuSample& s) override { return kf_.update(s); }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override { return kf_.q_world_body(); }
  [[nodiscard]] bool initialized() const override { return kf_.initialized(); }
  void reset() override { kf_.reset(); }
  void seed_field(double field_ut, double dip_deg) override {
    ParallelKfParams p = kf_.params();
    seed_field_reference(field_ut, dip_deg, p.field_magnitude_ut, p.dip_deg);
    kf_ = ParallelKf(p);
  }
  [[nodiscard]] std::map<std::string, uint64_t> rejections() const override {
    auto m = kf_.rejections().to_map();
    if (kf_.mag_gated_count() != 0) {
      m["mag_gated_disturbed"] = kf_.mag_gated_count();
    }
    if (kf_.state_resets() != 0) {
      m["state_reset"] = kf_.state_resets();
    }
    return m;
  }
  [[nodiscard]] std::optional<Eigen::Matrix3d> attitude_covariance() const override {
    if (!kf_.initialized()) {
      return std::nullopt;
    }
    return kf_.attitude_covariance();
  }
  [[nodiscard]] HeadingStatus heading_status() const override { return kf_.heading_status(); }
  [[nodiscard]] SourceReports sources() const override { return kf_.sources(); }
  /// Used unless imu_delay_s was configured (not NaN); throws std::invalid_argument outside
  /// [0, 0.05] s (set_imu_delay_s).
  bool take_published_imu_delay(double delay_s) override {
    if (delay_configured_) {
      return false;
    }
    kf_.set_imu_delay_s(delay_s);
    return true;
  }
  [[nodiscard]] const ParallelKf& core() const { return kf_; }

 private:
  ParallelKf kf_;
  bool delay_configured_ = false;  ///< imu_delay_s was set by the parameters (a published one is ignored)
};

}  // namespace poise
