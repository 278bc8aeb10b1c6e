// YAML loading of ParallelKfParams (the one loader shape, poise/core/yaml_params.h): keys under
// `parallel_kf:` or at the top level; `preset` (paper | default) picks the base, every other key
// is a field name (KF1's under `tilt:`, the sample limits under `limits:`; `tilt.x: v` is the
// same as `tilt: {x: v}`; the hard-iron estimator's keys under `hard_iron_estimator:`). Unknown
// keys and out-of-range values are errors naming the file and key.
#include "poise/parallel_kf/parallel_kf.h"

#include "poise/core/yaml_params.h"

#include <string>

namespace poise {

ParallelKfParams load_parallel_kf_params(const std::string& path, const ParallelKfParams& base) {
  return load_params_file(path, "parallel_kf parameter file", "parallel_kf", base,
                          [](YamlParamReader& r, ParallelKfParams& p) {
    r.get_with("preset", [&p](const YAML::Node& n) { p = ParallelKfParams::named(n.as<std::string>()); });
    YamlParamReader tilt = r.child("tilt");
    p.tilt.read(tilt);
    tilt.get("gravity_mps2", p.tilt.gravity_mps2);
    tilt.finish();
    r.get("sigma_gyro_heading_rps", p.sigma_gyro_heading_rps);
    r.get("sigma_mag_ut", p.sigma_mag_ut);
    r.get("c_d", p.c_d);
    r.get("c_d_rate_hz", p.c_d_rate_hz);
    r.get("sigma_gyro_extra_heading_rps", p.sigma_gyro_extra_heading_rps);
    r.get_nullable("field_magnitude_ut", p.field_magnitude_ut);
    r.get_nullable("dip_deg", p.dip_deg);
    r.get("startup_s", p.startup_s);
    r.get("gyro_current_weight", p.gyro_current_weight);
    r.get("coning_correction", p.coning_correction);
    r.get("quadratic_rate", p.quadratic_rate);
    r.get_nullable("imu_delay_s", p.imu_delay_s);
    r.get("accel_lowpass_tau_s", p.accel_lowpass_tau_s);
    r.get("accel_lowpass_order", p.accel_lowpass_order);
    r.get("share_tilt_correction", p.share_tilt_correction);
    r.get("bias_estimation", p.bias_estimation);
    r.get("rest_gyro_max_rps", p.rest_gyro_max_rps);
    r.get("rest_accel_max_mps2", p.rest_accel_max_mps2);
    r.get("rest_min_s", p.rest_min_s);
    r.get("rest_filter_tau_s", p.rest_filter_tau_s);
    r.get("bias_sigma_init_rps", p.bias_sigma_init_rps);
    r.get("bias_sigma_rest_rps", p.bias_sigma_rest_rps);
    r.get("bias_drift_rps", p.bias_drift_rps);
    r.get("bias_forgetting_time_s", p.bias_forgetting_time_s);
    r.get_nullable("gyro_bias_walk_rps_per_sqrt_s", p.gyro_bias_walk_rps_per_sqrt_s);
    r.get_nullable("gyro_initial_bias_sd_rps", p.gyro_initial_bias_sd_rps);
    r.get_nullable("gyro_noise_density_rps_per_sqrt_hz", p.gyro_noise_density_rps_per_sqrt_hz);
    r.get("motion_bias_sigma_rps", p.motion_bias_sigma_rps);
    r.get("motion_bias_heading", p.motion_bias_heading);
    r.get("motion_bias_clip_rps", p.motion_bias_clip_rps);
    r.get("motion_gyro_scale_error", p.motion_gyro_scale_error);
    r.get_nullable("gyro_scale_error", p.gyro_scale_error);
    r.get("max_bias_rps", p.max_bias_rps);
    r.get("mag_gating", p.mag_gating);
    r.get("mag_norm_tol", p.mag_norm_tol);
    r.get("mag_dip_tol_deg", p.mag_dip_tol_deg);
    r.get("mag_reference_tau_s", p.mag_reference_tau_s);
    r.get("mag_reacquire_s", p.mag_reacquire_s);
    r.get("mag_reacquire_tol", p.mag_reacquire_tol);
    r.get("mag_max_reject_s", p.mag_max_reject_s);
    r.get("mag_verify_s", p.mag_verify_s);
    r.get("mag_soft_weight", p.mag_soft_weight);
    r.get("mag_adaptive_noise", p.mag_adaptive_noise);
    r.get("hard_iron", p.hard_iron);
    YamlParamReader hi = r.child("hard_iron_estimator");
    p.hard_iron_estimator.read(hi);
    hi.finish();
    read_sample_limits(r, p.limits);
    read_magnetometer_use(r, p.use_magnetometer);
  });
}

}  // namespace poise
