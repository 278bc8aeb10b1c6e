// The selective EKF's parameter checks (ParamCheck: key as in the YAML file, range, unit) and
// the field gate its heading uses. Loading from YAML: params_yaml.cpp.
#include "update.h"

#include "poise/core/params_check.h"

#include <cmath>

namespace poise {

void validate(const SelectiveEkfParams& p) {
  const ParamCheck check("selective_ekf");
  check.positive(p.sigma_angular_accel, "sigma_angular_accel", "rad/s^2/sqrt(Hz)");
  check.positive(p.sigma_linear_accel, "sigma_linear_accel", "m/s^2/sqrt(Hz)");
  check.non_negative(p.sigma_attitude_walk, "sigma_attitude_walk", "rad/sqrt(s)");
  check.positive(p.sigma_gyro_rps, "sigma_gyro_rps", "rad/s");
  check.non_negative(p.sigma_bias_walk, "sigma_bias_walk", "rad/s/sqrt(s)");
  check.non_negative(p.accel_lowpass_tau_s, "accel_lowpass_tau_s", "s, 0 = raw accelerometer");
  check.require(std::isnan(p.sigma_tilt_rad_sqrt_s) || p.sigma_tilt_rad_sqrt_s > 0.0, "sigma_tilt_rad_sqrt_s",
                "> 0 (rad sqrt(s)) or null (derived from accel_lowpass_tau_s)");
  check.require(!std::isnan(p.sigma_tilt_rad_sqrt_s) || p.accel_lowpass_tau_s > 0.0, "accel_lowpass_tau_s",
                "> 0 (s) while sigma_tilt_rad_sqrt_s is null (it sets the tilt time constant)");
  check.non_negative(p.tilt_accel_ref_mps2, "tilt_accel_ref_mps2", "m/s^2, 0 = off");
  check.require(p.gravity_mps2 > 5.0 && p.gravity_mps2 < 15.0, "gravity_mps2", "in (5, 15) (m/s^2)");
  check.non_negative(p.output_max_correction_dps, "output_max_correction_dps", "deg/s, 0 = off");
  check.require(p.aiding_period_s >= 0.0 && p.aiding_period_s <= 1.0, "aiding_period_s", "in [0, 1] (s)");
  check.positive(p.sigma_heading_rad_sqrt_s, "sigma_heading_rad_sqrt_s", "rad sqrt(s)");
  check.require(p.gyro_scale_error >= 0.0 && p.gyro_scale_error < 1.0, "gyro_scale_error", "in [0, 1) (relative)");
  check.require(p.heading_disturbance_weight >= 0.0 && p.heading_disturbance_weight <= 1.0e6, "heading_disturbance_weight",
                "in [0, 1e6] (0 = off; larger would make the heading variance overflow)");
  p.hard_iron_estimator.validate("selective_ekf hard_iron_estimator");
  check.positive(p.rest_gyro_max_rps, "rest_gyro_max_rps", "rad/s");
  check.positive(p.rest_accel_max_mps2, "rest_accel_max_mps2", "m/s^2");
  check.non_negative(p.rest_min_s, "rest_min_s", "s");
  check.positive(p.rest_filter_tau_s, "rest_filter_tau_s", "s");
  check.positive(p.sigma_rest_rate_rps, "sigma_rest_rate_rps", "rad/s");
  check.positive(p.init_sigma_bias_rps, "init_sigma_bias_rps", "rad/s");
  check.positive(p.sigma_imu_quat_deg, "sigma_imu_quat_deg", "deg");
  check.positive(p.sigma_vision_deg, "sigma_vision_deg", "deg");
  check.positive(p.sigma_vision_m, "sigma_vision_m", "m");
  check.require(p.startup_samples >= 1, "startup_samples", ">= 1 (samples)");
  check.positive(p.disturbance_angle_threshold_deg, "disturbance_angle_threshold_deg", "deg");
  check.positive(p.mag_norm_threshold, "mag_norm_threshold", "relative");
  heading_field_gate(p).validate(check, {"field_magnitude_ut", "dip_deg", "field_startup_s", "heading_norm_tolerance",
                                          "heading_dip_tolerance_deg", "field_reference_tau_s", "field_reacquire_s",
                                          "field_reacquire_tol", "field_max_reject_s", "field_verify_s"});
  check.require(p.quat_error_threshold_deg > 0.0 && p.quat_error_threshold_deg <= 180.0,
                "quat_error_threshold_deg", "in (0, 180] (deg)");
  check.require(std::isfinite(p.inflate_factor) && p.inflate_factor >= 1.0, "inflate_factor", "finite and >= 1");
  check.non_negative(p.untrusted_hold_s, "untrusted_hold_s", "s");
  check.positive(p.q_error_lockout_s, "q_error_lockout_s", "s");
  check.positive(p.vision_anchor_s, "vision_anchor_s", "s");
  check.positive(p.vision_gate_sigma, "vision_gate_sigma", "standard deviations");
  check.require(p.vision_reset_after_rejections >= 1, "vision_reset_after_rejections", ">= 1 (samples)");
  check.require(p.history_s > 0.0 && p.history_s <= 5.0, "history_s", "in (0, 5] (s)");
  check.require(std::abs(p.vision_time_offset_s) <= 0.2, "vision_time_offset_s", "in [-0.2, 0.2] (s)");
  check.require(p.vision_time_offset_sigma_s >= 0.0 && p.vision_time_offset_sigma_s <= 0.2,
                "vision_time_offset_sigma_s", "in [0, 0.2] (s; 0 = not estimated)");
  check.require(p.vision_time_offset_walk_s_sqrt_s >= 0.0 && p.vision_time_offset_walk_s_sqrt_s <= 0.01,
                "vision_time_offset_walk_s_sqrt_s", "in [0, 0.01] (s/sqrt(s))");
  check.require(p.predict_horizon_s >= 0.0 && p.predict_horizon_s <= 0.2, "predict_horizon_s", "in [0, 0.2] (s)");
  check.require(std::isnan(p.imu_delay_s) || (p.imu_delay_s >= 0.0 && p.imu_delay_s <= 0.05), "imu_delay_s",
                "in [0, 0.05] (s), or null (not known: half a sample)");
  // figures of the sensor (P_err only): null = not known
  check.require(std::isnan(p.gyro_noise_density_rps_per_sqrt_hz) ||
                    (p.gyro_noise_density_rps_per_sqrt_hz > 0.0 && p.gyro_noise_density_rps_per_sqrt_hz <= 0.01),
                "gyro_noise_density_rps_per_sqrt_hz", "in (0, 0.01] (rad/s/sqrt(Hz)), or null (not known: sigma_gyro_rps)");
  check.require(std::isnan(p.accel_noise_density_mps2_per_sqrt_hz) ||
                    (p.accel_noise_density_mps2_per_sqrt_hz > 0.0 && p.accel_noise_density_mps2_per_sqrt_hz <= 1.0),
                "accel_noise_density_mps2_per_sqrt_hz",
                "in (0, 1] (m/s^2/sqrt(Hz)), or null (not known: the tilt density as white noise)");
  check.require(std::isnan(p.gyro_bias_walk_rps_per_sqrt_s) ||
                    (p.gyro_bias_walk_rps_per_sqrt_s >= 0.0 && p.gyro_bias_walk_rps_per_sqrt_s <= 0.01),
                "gyro_bias_walk_rps_per_sqrt_s", "in [0, 0.01] (rad/s/sqrt(s)), or null (not known: sigma_bias_walk)");
  check.require(selective_ekf_aids::finite_quat(p.q_body_camera), "q_body_camera", "a finite unit quaternion [w, x, y, z]");
  check.require(p.p_body_camera_m.allFinite(), "p_body_camera_m", "finite (m)");
  check.positive(p.init_sigma_attitude_deg, "init_sigma_attitude_deg", "deg");
  check.positive(p.init_sigma_rate_rps, "init_sigma_rate_rps", "rad/s");
  check.positive(p.init_sigma_position_m, "init_sigma_position_m", "m");
  check.positive(p.init_sigma_velocity_mps, "init_sigma_velocity_mps", "m/s");
  validate(p.limits, check);
  p.gauss_newton.validate("selective_ekf.gauss_newton");
}

FieldGateParams heading_field_gate(const SelectiveEkfParams& p) {
  FieldGateParams g;
  g.enabled = p.gating_enabled;
  g.field_magnitude_ut = p.field_magnitude_ut;
  g.dip_deg = p.dip_deg;
  g.startup_s = p.field_startup_s;
  g.norm_tol = p.heading_norm_tolerance;
  g.dip_tol_deg = p.heading_dip_tolerance_deg;
  g.reference_tau_s = p.field_reference_tau_s;
  g.reacquire_s = p.field_reacquire_s;
  g.reacquire_tol = p.field_reacquire_tol;
  g.max_reject_s = p.field_max_reject_s;
  g.verify_s = p.field_verify_s;
  return g;
}

}  // namespace poise
