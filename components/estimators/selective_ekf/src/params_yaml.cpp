// YAML -> SelectiveEkfParams (config/filters/selective_ekf*.yaml), the one loader shape
// (poise/core/yaml_params.h). Defaults live in the struct; the file only overrides. Unknown keys
// are errors so a typo never silently keeps a default.
#include "poise/selective_ekf/selective_ekf.h"

#include "poise/core/yaml_params.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace poise {
namespace {

Eigen::Quaterniond as_quat_wxyz(const YAML::Node& n) {
  if (!n.IsSequence() || n.size() != 4) {
    throw std::runtime_error("expected [w, x, y, z]");
  }
  const Eigen::Quaterniond q(n[0].as<double>(), n[1].as<double>(), n[2].as<double>(),
                             n[3].as<double>());
  if (!q.coeffs().allFinite() || std::abs(q.coeffs().norm() - 1.0) > 1e-3) {
    throw std::runtime_error("quaternion must be unit length (|q| within 1e-3 of 1)");
  }
  return q.normalized();
}

void read(YamlParamReader& r, SelectiveEkfParams& p) {
  r.get("sigma_angular_accel", p.sigma_angular_accel);
  r.get("sigma_linear_accel", p.sigma_linear_accel);
  r.get("sigma_attitude_walk", p.sigma_attitude_walk);
  r.get("sigma_bias_walk", p.sigma_bias_walk);
  r.get("sigma_gyro_rps", p.sigma_gyro_rps);
  r.get_enum("imu_measurement", p.imu_measurement,
             {{"split", ImuMeasurement::kSplit}, {"quaternion", ImuMeasurement::kQuaternion}});
  r.get("accel_lowpass_tau_s", p.accel_lowpass_tau_s);
  r.get_nullable("sigma_tilt_rad_sqrt_s", p.sigma_tilt_rad_sqrt_s);
  r.get("tilt_accel_ref_mps2", p.tilt_accel_ref_mps2);
  r.get("gravity_mps2", p.gravity_mps2);
  r.get("aiding_period_s", p.aiding_period_s);
  r.get("heading_dip_tolerance_deg", p.heading_dip_tolerance_deg);
  r.get("heading_norm_tolerance", p.heading_norm_tolerance);
  r.get("heading_disturbance_weight", p.heading_disturbance_weight);
  r.get("hard_iron", p.hard_iron);
  YamlParamReader hi = r.child("hard_iron_estimator");
  p.hard_iron_estimator.read(hi);
  hi.finish();
  r.get_nullable("field_magnitude_ut", p.field_magnitude_ut);
  r.get("field_startup_s", p.field_startup_s);
  r.get("field_reference_tau_s", p.field_reference_tau_s);
  r.get("field_reacquire_s", p.field_reacquire_s);
  r.get("field_reacquire_tol", p.field_reacquire_tol);
  r.get("field_max_reject_s", p.field_max_reject_s);
  r.get("field_verify_s", p.field_verify_s);
  r.get("sigma_heading_rad_sqrt_s", p.sigma_heading_rad_sqrt_s);
  r.get("gyro_scale_error", p.gyro_scale_error);
  r.get_nullable("gyro_noise_density_rps_per_sqrt_hz", p.gyro_noise_density_rps_per_sqrt_hz);
  r.get_nullable("accel_noise_density_mps2_per_sqrt_hz", p.accel_noise_density_mps2_per_sqrt_hz);
  r.get_nullable("gyro_bias_walk_rps_per_sqrt_s", p.gyro_bias_walk_rps_per_sqrt_s);
  r.get("rest_detection", p.rest_detection);
  r.get("rest_gyro_max_rps", p.rest_gyro_max_rps);
  r.get("rest_accel_max_mps2", p.rest_accel_max_mps2);
  r.get("rest_min_s", p.rest_min_s);
  r.get("rest_filter_tau_s", p.rest_filter_tau_s);
  r.get("sigma_rest_rate_rps", p.sigma_rest_rate_rps);
  r.get("sigma_imu_quat_deg", p.sigma_imu_quat_deg);
  r.get("sigma_vision_deg", p.sigma_vision_deg);
  r.get("sigma_vision_m", p.sigma_vision_m);
  r.get("gating_enabled", p.gating_enabled);
  r.get_enum("up_source", p.up_source, {{"raw_accel", UpSource::kRawAccel}, {"filtered", UpSource::kFiltered}});
  r.get_nullable("dip_deg", p.dip_deg);
  r.get("startup_samples", p.startup_samples);
  r.get("disturbance_angle_threshold_deg", p.disturbance_angle_threshold_deg);
  r.get("mag_norm_test", p.mag_norm_test);
  r.get("mag_norm_threshold", p.mag_norm_threshold);
  r.get("quat_error_test", p.quat_error_test);
  r.get("quat_error_threshold_deg", p.quat_error_threshold_deg);
  r.get_enum("action", p.action, {{"inflate", ImuQuatAction::kInflate}, {"drop", ImuQuatAction::kDrop}});
  r.get("inflate_factor", p.inflate_factor);
  r.get("untrusted_hold_s", p.untrusted_hold_s);
  r.get("q_error_lockout_s", p.q_error_lockout_s);
  r.get("vision_anchor_s", p.vision_anchor_s);
  r.get("vision_gate_sigma", p.vision_gate_sigma);
  r.get("vision_reset_after_rejections", p.vision_reset_after_rejections);
  r.get("history_s", p.history_s);
  r.get("vision_time_offset_s", p.vision_time_offset_s);
  r.get("vision_time_offset_sigma_s", p.vision_time_offset_sigma_s);
  r.get("vision_time_offset_walk_s_sqrt_s", p.vision_time_offset_walk_s_sqrt_s);
  r.get("predict_horizon_s", p.predict_horizon_s);
  r.get_nullable("imu_delay_s", p.imu_delay_s);
  r.get("output_max_correction_dps", p.output_max_correction_dps);
  r.get_with("q_body_camera", [&p](const YAML::Node& n) { p.q_body_camera = as_quat_wxyz(n); });
  r.get("p_body_camera_m", p.p_body_camera_m);
  r.get("init_sigma_attitude_deg", p.init_sigma_attitude_deg);
  r.get("init_sigma_rate_rps", p.init_sigma_rate_rps);
  r.get("init_sigma_bias_rps", p.init_sigma_bias_rps);
  r.get("init_sigma_position_m", p.init_sigma_position_m);
  r.get("init_sigma_velocity_mps", p.init_sigma_velocity_mps);
  // the sample limits are top-level keys here (limits.* in the other filters' files)
  r.get("max_dt_s", p.limits.max_dt_s);
  r.get("min_accel_norm_mps2", p.limits.min_accel_norm_mps2);
  r.get("min_mag_norm_ut", p.limits.min_mag_norm_ut);
  r.get("max_gyro_rps", p.limits.max_gyro_rps);
  r.get("max_accel_mps2", p.limits.max_accel_mps2);
  r.get("max_mag_ut", p.limits.max_mag_ut);
  read_magnetometer_use(r, p.use_magnetometer);
  YamlParamReader gn = r.child("gauss_newton");
  p.gauss_newton.read(gn);
  gn.finish();
  p.gauss_newton.limits = p.limits;
}

}  // namespace

void SelectiveEkfParams::validate() const { poise::validate(*this); }

SelectiveEkfParams load_selective_ekf_params(const std::string& path) {
  return load_params_file(path, "selective EKF parameter file", "selective_ekf", SelectiveEkfParams{}, read);
}

}  // namespace poise
