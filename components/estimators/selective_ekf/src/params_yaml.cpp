// YAML -> SelectiveEkfParams (config/filters/selective_ekf*.yaml). Defaults live in the struct;
// the file only overrides. Unknown keys are errors so a typo never silently keeps a default.
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/core/yaml_params.h"

#include <yaml-cpp/yaml.h>

#include <functional>
#include <stdexcept>

namespace poise {
namespace {

double as_nullable_double(const YAML::Node& n) {
  return n.IsNull() ? std::nan("") : n.as<double>();
}

Eigen::Vector3d as_vec3(const YAML::Node& n) {
  if (!n.IsSequence() || n.size() != 3) {
    throw std::runtime_error("expected a list of 3 numbers");
  }
  return {n[0].as<double>(), n[1].as<double>(), n[2].as<double>()};
}

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

using Setter = std::function<void(const YAML::Node&)>;

void apply(const YAML::Node& node, const std::map<std::string, Setter>& setters,
           const std::string& path, const std::string& section) {
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    const auto it = setters.find(key);
    try {
      if (it == setters.end()) {
        throw std::runtime_error("unknown key");
      }
      it->second(kv.second);
    } catch (const std::exception& e) {
      std::string keys;
      for (const auto& s : setters) {
        keys += (keys.empty() ? "" : ", ") + s.first;
      }
      throw std::runtime_error(path + ": " + section + "." + key + ": " + e.what() +
                               " (keys: " + keys + ")");
    }
  }
}

}  // namespace

// not split: one table of keys read in the file's documented order, each line a key and its unit.
SelectiveEkfParams load_selective_ekf_params(const std::string& path) {
  YAML::Node root;
  try {
    root = load_yaml_file(path, "selective EKF config");
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot read selective EKF config '" + path + "': " + e.what());
  }
  if (!root["selective_ekf"]) {
    throw std::runtime_error(path + ": missing top-level key 'selective_ekf'");
  }
  SelectiveEkfParams p;
  auto d = [](double& f) { return [&f](const YAML::Node& n) { f = n.as<double>(); }; };
  auto b = [](bool& f) { return [&f](const YAML::Node& n) { f = n.as<bool>(); }; };
  auto i = [](int& f) { return [&f](const YAML::Node& n) { f = n.as<int>(); }; };
  GaussNewtonParams& gn = p.gauss_newton;
  const std::map<std::string, Setter> gn_setters = {
      {"max_iterations", i(gn.max_iterations)},
      {"tolerance_rad", d(gn.tolerance_rad)},
      {"mag_weight", d(gn.mag_weight)},
      {"dip_deg", [&gn](const YAML::Node& n) { gn.dip_deg = as_nullable_double(n); }},
      {"startup_samples", i(gn.startup_samples)},
  };
  const std::map<std::string, Setter> setters = {
      {"sigma_angular_accel", d(p.sigma_angular_accel)},
      {"sigma_linear_accel", d(p.sigma_linear_accel)},
      {"sigma_attitude_walk", d(p.sigma_attitude_walk)},
      {"sigma_bias_walk", d(p.sigma_bias_walk)},
      {"sigma_gyro_rps", d(p.sigma_gyro_rps)},
      {"imu_measurement",
       [&p](const YAML::Node& n) {
         const std::string s = n.as<std::string>();
         if (s == "split") {
           p.imu_measurement = ImuMeasurement::kSplit;
         } else if (s == "quaternion") {
           p.imu_measurement = ImuMeasurement::kQuaternion;
         } else {
           throw std::runtime_error("must be split or quaternion");
         }
       }},
      {"accel_lowpass_tau_s", d(p.accel_lowpass_tau_s)},
      {"sigma_tilt_rad_sqrt_s", [&p](const YAML::Node& n) { p.sigma_tilt_rad_sqrt_s = as_nullable_double(n); }},
      {"tilt_accel_ref_mps2", d(p.tilt_accel_ref_mps2)},
      {"gravity_mps2", d(p.gravity_mps2)},
      {"aiding_period_s", d(p.aiding_period_s)},
      {"heading_dip_tolerance_deg", d(p.heading_dip_tolerance_deg)},
      {"heading_norm_tolerance", d(p.heading_norm_tolerance)},
      {"heading_disturbance_weight", d(p.heading_disturbance_weight)},
      {"field_magnitude_ut", [&p](const YAML::Node& n) { p.field_magnitude_ut = as_nullable_double(n); }},
      {"field_startup_s", d(p.field_startup_s)},
      {"field_reference_tau_s", d(p.field_reference_tau_s)},
      {"field_reacquire_s", d(p.field_reacquire_s)},
      {"field_reacquire_tol", d(p.field_reacquire_tol)},
      {"field_max_reject_s", d(p.field_max_reject_s)},
      {"sigma_heading_rad_sqrt_s", d(p.sigma_heading_rad_sqrt_s)},
      {"rest_detection", b(p.rest_detection)},
      {"rest_gyro_max_rps", d(p.rest_gyro_max_rps)},
      {"rest_accel_max_mps2", d(p.rest_accel_max_mps2)},
      {"rest_min_s", d(p.rest_min_s)},
      {"rest_filter_tau_s", d(p.rest_filter_tau_s)},
      {"sigma_rest_rate_rps", d(p.sigma_rest_rate_rps)},
      {"sigma_imu_quat_deg", d(p.sigma_imu_quat_deg)},
      {"sigma_vision_deg", d(p.sigma_vision_deg)},
      {"sigma_vision_m", d(p.sigma_vision_m)},
      {"gating_enabled", b(p.gating_enabled)},
      {"up_source",
       [&p](const YAML::Node& n) {
         const std::string s = n.as<std::string>();
         if (s == "raw_accel") {
           p.up_source = UpSource::kRawAccel;
         } else if (s == "filtered") {
           p.up_source = UpSource::kFiltered;
         } else {
           throw std::runtime_error("must be raw_accel or filtered");
         }
       }},
      {"dip_deg", [&p](const YAML::Node& n) { p.dip_deg = as_nullable_double(n); }},
      {"startup_samples", i(p.startup_samples)},
      {"disturbance_angle_threshold_deg", d(p.disturbance_angle_threshold_deg)},
      {"mag_norm_test", b(p.mag_norm_test)},
      {"mag_norm_threshold", d(p.mag_norm_threshold)},
      {"quat_error_test", b(p.quat_error_test)},
      {"quat_error_threshold_deg", d(p.quat_error_threshold_deg)},
      {"action",
       [&p](const YAML::Node& n) {
         const std::string s = n.as<std::string>();
         if (s == "inflate") {
           p.action = ImuQuatAction::kInflate;
         } else if (s == "drop") {
           p.action = ImuQuatAction::kDrop;
         } else {
           throw std::runtime_error("must be inflate or drop");
         }
       }},
      {"inflate_factor", d(p.inflate_factor)},
      {"untrusted_hold_s", d(p.untrusted_hold_s)},
      {"q_error_lockout_s", d(p.q_error_lockout_s)},
      {"vision_anchor_s", d(p.vision_anchor_s)},
      {"vision_gate_sigma", d(p.vision_gate_sigma)},
      {"vision_reset_after_rejections", i(p.vision_reset_after_rejections)},
      {"history_s", d(p.history_s)},
      {"vision_time_offset_s", d(p.vision_time_offset_s)},
      {"imu_delay_s", d(p.imu_delay_s)},
      {"output_max_correction_dps", d(p.output_max_correction_dps)},
      {"q_body_camera", [&p](const YAML::Node& n) { p.q_body_camera = as_quat_wxyz(n); }},
      {"p_body_camera_m", [&p](const YAML::Node& n) { p.p_body_camera_m = as_vec3(n); }},
      {"init_sigma_attitude_deg", d(p.init_sigma_attitude_deg)},
      {"init_sigma_rate_rps", d(p.init_sigma_rate_rps)},
      {"init_sigma_bias_rps", d(p.init_sigma_bias_rps)},
      {"init_sigma_position_m", d(p.init_sigma_position_m)},
      {"init_sigma_velocity_mps", d(p.init_sigma_velocity_mps)},
      {"max_dt_s", d(p.limits.max_dt_s)},
      {"min_accel_norm_mps2", d(p.limits.min_accel_norm_mps2)},
      {"min_mag_norm_ut", d(p.limits.min_mag_norm_ut)},
      {"max_gyro_rps", d(p.limits.max_gyro_rps)},
      {"max_accel_mps2", d(p.limits.max_accel_mps2)},
      {"max_mag_ut", d(p.limits.max_mag_ut)},
      {"use_magnetometer", [&p](const YAML::Node& n) { p.use_magnetometer = read_magnetometer_use(n); }},
      {"gauss_newton",
       [&](const YAML::Node& n) {
         if (!n.IsMap()) {
           throw std::runtime_error("expected a map");
         }
         apply(n, gn_setters, path, "selective_ekf.gauss_newton");
       }},
  };
  apply(root["selective_ekf"], setters, path, "selective_ekf");
  gn.limits = p.limits;
  try {
    validate(p);
    GaussNewton check(gn);  // throws on bad Gauss-Newton parameters
    (void)check;
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
  return p;
}

}  // namespace poise
