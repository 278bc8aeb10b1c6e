// VehicleEstimator: vehicle roll, pitch and yaw from lateral/longitudinal acceleration, yaw rate,
// a 3-axis magnetometer and the vehicle speed (paper 001, Y. Hwang and S. Choi, Trans. KSAE 2016;
// readings in ESTIMATORS.md section 6).
//
// Frames and angles (ours; the paper's figures use SAE axes, we keep the project's conventions)
//   world ENU (x east, y north, z up); vehicle/body FLU (x forward, y left, z up) = the sensor axes.
//   phi, theta, psi: roll, pitch, yaw, intrinsic Z-Y-X: R_world_body = Rz(psi) Ry(theta) Rx(phi).
//   theta > 0 is nose DOWN, phi > 0 is left side UP; psi counter-clockwise from east (magnetic).
//   R(phi, theta, psi) of (1) = R_world_body^T maps world vectors into the body: B_m = R H.
//   phi = phi_v + phi_r, theta = theta_v + theta_r (vehicle on its suspension + road)  (2)
// Signals: a_x, a_y specific force along body x, y (m/s^2; the paper uses g units), r the body-z
//   rate (yaw-rate sensor, rad/s), B the magnetometer (uT), v the speed (m/s); H the local field
//   in ENU (uT).
// Static (|r| < r_max and v < v_max): TRIAD (9) with the virtual "up" measurement (7)
//   g_m = [0, a_y/g, sqrt(1 - (a_y/g)^2)] against the world up [0, 0, 1]; r3 = normalise(r1 x r2)
//   (the print repeats s); Euler angles (10) with atan2.
// Dynamic: 5-state EKF (11)-(13), x = [phi, phi_dot, theta, theta_dot, psi] (the printed 3-vector on
//   the left of (11) is a typo):
//     d/dt phi       = phi_dot + cos(phi) sin(theta) r
//     d/dt phi_dot   = (-k_x phi - b_x phi_dot + m_s h_s a_y) / I_x
//     d/dt theta     = theta_dot - sin(phi) r
//     d/dt theta_dot = (-k_y theta - b_y theta_dot - m_s h_s a_x) / I_y
//     d/dt psi       = cos(phi) cos(theta) r
//   The input signs differ from the print (-a_y, +a_x in SAE x-forward/y-right/z-down axes) only
//   because of the FLU axes: in both, the body rolls out of a turn and squats when accelerating.
//   The yaw-rate term is as printed ((3): first-order Euler kinematics with p = q = 0).
//   Discretised with forward Euler: F = I + J dt, Q = diag[s_x, 0, s_y, 0, s_z] dt (Q of (13) read
//   as densities, rad^2/s). Measurement (12): B = R(phi, theta, psi) H ((1,2) entry C(theta)S(psi)
//   as in (1), not the printed C(theta)C(psi)); R = diag[R_x, R_y, R_z] (uT^2). Joseph update.
// Switching: static -> TRIAD, and the EKF is re-initialised at the TRIAD angles (zero rates);
//   dynamic -> EKF. Modes `triad` and `ekf` run one of them alone (for comparisons).
//   Extension (switchable, `static_average`, default on): while static, TRIAD uses the mean of the
//   magnetometer and a_y since the stop began instead of the last sample (noise / sqrt(N)).
// Known limitation (paper 001 conclusion): the spring-damper pulls the TOTAL roll to the suspension
//   equilibrium, so on a banked road the model fights the magnetometer and the bank is
//   underestimated while driving (measured in docs/ESTIMATORS_ALTITUDE_VEHICLE.md).
#pragma once

#include "poise/core/sample_check.h"
#include "poise/core/source_report.h"
#include "poise/core/state_health.h"
#include "poise/core/types.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <string>

namespace poise {

/// Vehicle roll/pitch model parameters of (5), (6), (11). Defaults: a mid-size sedan (roll
/// gradient ~5 deg/g, pitch gradient ~2 deg/g, roll/pitch modes ~2 Hz / ~1.6 Hz, damping ~0.5).
struct VehicleModelParams {
  double i_x_kgm2 = 500.0;      ///< sprung-mass roll inertia I_x, kg m^2
  double i_y_kgm2 = 2000.0;     ///< sprung-mass pitch inertia I_y, kg m^2
  double k_x_nm_per_rad = 80000.0;   ///< roll stiffness k_x, N m/rad. Raising it: less roll per g.
  double k_y_nm_per_rad = 200000.0;  ///< pitch stiffness k_y, N m/rad
  double b_x_nms_per_rad = 6000.0;   ///< roll damping b_x, N m s/rad
  double b_y_nms_per_rad = 20000.0;  ///< pitch damping b_y, N m s/rad
  double m_s_kg = 1400.0;       ///< sprung mass m_s, kg
  double h_s_m = 0.5;           ///< roll-centre to CG height h_s, m
};

enum class VehicleMode {
  kSwitched,  ///< TRIAD when static, EKF when dynamic (the paper's estimator)
  kTriad,     ///< TRIAD alone (every sample)
  kEkf,       ///< EKF alone (initialised once from TRIAD)
};
const char* to_string(VehicleMode m);
bool parse_vehicle_mode(const std::string& name, VehicleMode& out);

struct VehicleParams {
  VehicleModelParams model;
  VehicleMode mode = VehicleMode::kSwitched;
  double gravity_mps2 = 9.80665;                ///< g, m/s^2 (a_y / g in (7))
  Eigen::Vector3d mag_world_ut{0.0, 30.0, -40.0};  ///< H in ENU, uT (default ~Korea: 30 uT north, 40 uT down, declination folded into "magnetic" yaw)

  // Switching (section 3.2, last paragraph)
  double static_yaw_rate_max_rps = 0.02;       ///< static when |r| below this (rad/s) ...
  double static_speed_max_mps = 0.5;           ///< ... and v below this (m/s)
  /// While static, run TRIAD on the mean magnetometer and a_y since the stop began (the vehicle
  /// does not move, so averaging only removes noise). Off: per-sample TRIAD as in the paper.
  bool static_average = true;

  // EKF noise (13)
  double q_roll_rad2_per_s = 1e-3;             ///< s_x: roll process noise density, rad^2/s. Raising it lets the magnetometer pull roll harder (less bank bias, more noise).
  double q_pitch_rad2_per_s = 1e-3;            ///< s_y: pitch, rad^2/s
  double q_yaw_rad2_per_s = 1e-4;              ///< s_z: yaw, rad^2/s (yaw-rate sensor noise and bias)
  Eigen::Vector3d r_mag_ut2{0.25, 0.25, 0.25};  ///< [R_x, R_y, R_z]: magnetometer noise variances, uT^2 (HMC5883L ~0.2 uT + residual calibration)
  double initial_var_angle_rad2 = 1e-3;        ///< P of phi, theta, psi at (re)initialisation
  double initial_var_rate_rad2ps2 = 1e-3;      ///< P of phi_dot, theta_dot

  // Input validation: the shared check (poise/core/sample_check.h) on [a_x, a_y], r and B
  double max_dt_s = 0.2;                       ///< a larger stamp gap is refused and re-anchors time (counted)
  double max_yaw_rate_rps = SampleLimits{}.max_gyro_rps;  ///< |r| above: sample rejected, rad/s (YAML limits.*)
  double max_accel_mps2 = SampleLimits{}.max_accel_mps2;  ///< |[a_x, a_y]| above: sample rejected, m/s^2
  double max_mag_ut = SampleLimits{}.max_mag_ut;          ///< |B| above: magnetometer rejected, uT
  double mag_norm_tolerance = 0.5;             ///< |B| outside (1 +- this) |H| is rejected as disturbed
  /// `use_magnetometer`: auto (default) = B when the sample carries one (has_mag); false = never
  /// (yaw from r alone, not counted as missing_mag); true = every sample must carry one (a sample
  /// without is refused, counted no_magnetometer).
  MagnetometerUse use_magnetometer = MagnetometerUse::kAuto;

  /// Throws std::invalid_argument naming the first key out of range, its range and unit (ParamCheck).
  void validate() const;
};

/// Loads VehicleParams from YAML (config/filters/vehicle.yaml); unknown keys and bad values throw
/// std::runtime_error naming the file and the key.
VehicleParams load_vehicle_params(const std::string& path);

/// One input sample (all signals sampled at stamp_ns).
struct VehicleSample {
  int64_t stamp_ns = 0;
  double accel_lon_mps2 = 0.0;    ///< a_x: specific force along body x (forward), m/s^2
  double accel_lat_mps2 = 0.0;    ///< a_y: specific force along body y (left), m/s^2
  double yaw_rate_rps = 0.0;      ///< r: body-z angular rate, rad/s
  Eigen::Vector3d mag_ut{0.0, 0.0, 0.0};  ///< B_m: magnetometer, body frame, uT
  bool has_mag = false;           ///< B_m valid: only when the source says so (as ImuSample::has_mag)
  double speed_mps = 0.0;         ///< v: forward speed over ground, m/s (>= 0)
  bool has_speed = true;
};

/// The vehicle sample of an IMU sample whose body axes are the vehicle's (x forward, y left, z up),
/// with the latest speed input: a_x, a_y = accel x, y; r = gyro z; B = mag (has_mag kept).
VehicleSample vehicle_sample_from_imu(const ImuSample& imu, bool has_speed, double speed_mps);

struct VehicleEstimate {
  int64_t stamp_ns = 0;
  double roll_rad = 0.0;
  double pitch_rad = 0.0;
  double yaw_rad = 0.0;                 ///< (-pi, pi], from east, counter-clockwise
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();
  bool is_static = false;               ///< switching condition of the last sample
  bool from_triad = false;              ///< the output came from TRIAD (else from the EKF)
  bool valid = false;
};

struct VehicleRejects {
  /// The shared check (check_imu_sample on a_x, a_y, r, B) per reason: non-finite or beyond full
  /// scale, stamp out of range, not after the last one, gap: sample rejected, state untouched;
  /// a non-finite, zero or beyond-full-scale magnetometer: treated as missing.
  RejectCounters samples;
  uint64_t bad_speed = 0;         ///< speed negative, NaN or missing: last valid speed kept
  uint64_t missing_mag = 0;       ///< no magnetometer: EKF predicts only, TRIAD holds
  uint64_t disturbed_mag = 0;     ///< |B| far from |H|: treated as missing
  [[nodiscard]] uint64_t total() const { return samples.total() + bad_speed + missing_mag + disturbed_mag; }
};

/// TRIAD (9) with the virtual gravity (7): R_body_world (matrix (1)) from the magnetometer, a_y
/// and the world field. False when the vectors are degenerate (zero or parallel).
bool triad_body_world(const Eigen::Vector3d& mag_body_ut, double accel_lat_g,
                      const Eigen::Vector3d& mag_world_ut, Eigen::Matrix3d& r_body_world);
/// Euler angles (10) [roll, pitch, yaw] of a matrix (1) (atan2; asin argument clamped).
Eigen::Vector3d euler_from_body_world(const Eigen::Matrix3d& r_body_world);
/// Matrix (1): R_body_world of roll, pitch, yaw.
Eigen::Matrix3d body_world_from_euler(double roll_rad, double pitch_rad, double yaw_rad);

/// Everything the vehicle estimator carries from one sample to the next besides its parameters:
/// inspect it, save it, restore it into an estimator with the same parameters (`set_state`).
struct VehicleEstimatorState {
  VehicleEstimate est;
  VehicleRejects rejects;
  bool have_stamp = false;
  int64_t last_stamp_ns = 0;
  StampAnchor anchor;  ///< restarts time after a stamp jump (two agreeing samples)
  double last_speed_mps = 0.0;
  bool ekf_init = false;
  Eigen::Matrix<double, 5, 1> x = Eigen::Matrix<double, 5, 1>::Zero();  ///< [phi, phi_dot, theta, theta_dot, psi]
  Eigen::Matrix<double, 5, 5> p = Eigen::Matrix<double, 5, 5>::Zero();  ///< its covariance
  // Static averaging
  Eigen::Vector3d static_mag_sum{0.0, 0.0, 0.0};
  double static_ay_sum = 0.0;
  uint64_t static_count = 0;
  // Inputs of sample k-1 (the EKF propagates from k-1 to k with them).
  double prev_ax = 0.0;
  double prev_ay = 0.0;
  double prev_r = 0.0;
  // Per-source reports of the last sample.
  SourceReport yaw_rate{Source::kYawRate};
  SourceReport accel{Source::kAccel};
  SourceReport mag{Source::kMag};
  SourceReport speed{Source::kSpeed};
  StateHealth health;  ///< resets after an unhealthy update (poise/core/state_health.h)
};

class VehicleEstimator {
 public:
  using Vector5 = Eigen::Matrix<double, 5, 1>;
  using Matrix5 = Eigen::Matrix<double, 5, 5>;

  /// Throws std::invalid_argument when params.validate() does.
  explicit VehicleEstimator(const VehicleParams& params = {});

  /// Back to the state of a new estimator (parameters kept).
  void reset();
  /// The estimator's whole state: two estimators with the same parameters and state give the
  /// same outputs for the same samples.
  [[nodiscard]] const VehicleEstimatorState& state() const { return s_; }
  /// Restores a state taken from state() of an estimator with the same parameters.
  void set_state(const VehicleEstimatorState& state) { s_ = state; }
  /// Returns false when the sample was rejected as a whole, and when the update left the state
  /// non-finite or P not a covariance: the estimator is then reset (counters kept), counted in
  /// state_resets() and starts again from the next sample.
  bool update(const VehicleSample& sample);
  /// Resets after an unhealthy state (poise/core/state_health.h).
  [[nodiscard]] uint64_t state_resets() const { return s_.health.resets; }

  [[nodiscard]] const VehicleEstimate& estimate() const { return s_.est; }
  [[nodiscard]] const VehicleRejects& rejects() const { return s_.rejects; }
  [[nodiscard]] const VehicleParams& params() const { return params_; }
  /// EKF state [phi, phi_dot, theta, theta_dot, psi] and covariance.
  [[nodiscard]] const Vector5& ekf_state() const { return s_.x; }
  [[nodiscard]] const Matrix5& ekf_covariance() const { return s_.p; }
  [[nodiscard]] bool ekf_initialized() const { return s_.ekf_init; }
  /// Per source for the last sample, in this order: yaw_rate (the EKF's propagation input), accel
  /// (a_x, a_y: EKF input and TRIAD's virtual gravity), mag (innovation: |B| - |H|, uT, against
  /// the disturbance tolerance: test ratio > 1 = rejected "disturbed_mag"), speed (the switching
  /// input; rejected "bad_speed" when negative or NaN, the last valid speed is then kept).
  [[nodiscard]] SourceReports sources() const { return {s_.yaw_rate, s_.accel, s_.mag, s_.speed}; }

 private:
  void ekf_init(const Eigen::Vector3d& euler);
  void ekf_predict(double a_x, double a_y, double r, double dt_s);
  void ekf_correct(const Eigen::Vector3d& mag_ut);
  void set_output(const Eigen::Vector3d& euler, bool from_triad);
  void reject_sample(const char* why);
  [[nodiscard]] bool healthy();
  void reset_unhealthy();  ///< reset() keeping the counters, one reset counted

  VehicleParams params_;
  SampleLimits limits_;  ///< the shared check's limits, from the parameters
  VehicleEstimatorState s_;
};

}  // namespace poise
