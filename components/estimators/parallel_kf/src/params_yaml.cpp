// YAML loading of ParallelKfParams: `preset` picks the base (paper | default), every other key
// is a field name (tilt fields prefixed `tilt.` or nested under `tilt:`). Unknown keys are errors.
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/core/yaml_params.h"

#include "poise/core/params_check.h"

#include <yaml-cpp/yaml.h>

#include <functional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace poise {
namespace {

struct Field {
  std::string name;
  std::function<void(ParallelKfParams&, const YAML::Node&)> set;
};

double as_double_or_nan(const YAML::Node& n) {
  if (n.IsNull()) {
    return std::nan("");
  }
  return n.as<double>();
}

template <typename T>
Field make(const std::string& name, T ParallelKfParams::*member) {
  return {name, [member](ParallelKfParams& p, const YAML::Node& n) { p.*member = n.as<T>(); }};
}
template <typename T>
Field make_tilt(const std::string& name, T TiltKfParams::*member) {
  return {"tilt." + name, [member](ParallelKfParams& p, const YAML::Node& n) { p.tilt.*member = n.as<T>(); }};
}
template <typename T>
Field make_limits(const std::string& name, T SampleLimits::*member) {
  return {"limits." + name,
          [member](ParallelKfParams& p, const YAML::Node& n) { p.limits.*member = n.as<T>(); }};
}

const std::vector<Field>& fields() {
  static const std::vector<Field> f = {
      make_tilt("sigma_gyro_rps", &TiltKfParams::sigma_gyro_rps),
      make_tilt("sigma_accel_mps2", &TiltKfParams::sigma_accel_mps2),
      make_tilt("c_a", &TiltKfParams::c_a),
      make_tilt("c_a_rate_hz", &TiltKfParams::c_a_rate_hz),
      make_tilt("gravity_mps2", &TiltKfParams::gravity_mps2),
      make_tilt("exact_rotation", &TiltKfParams::exact_rotation),
      make_tilt("renormalize", &TiltKfParams::renormalize),
      make_tilt("sigma_gyro_extra_rps", &TiltKfParams::sigma_gyro_extra_rps),
      make("sigma_gyro_heading_rps", &ParallelKfParams::sigma_gyro_heading_rps),
      make("sigma_mag_ut", &ParallelKfParams::sigma_mag_ut),
      make("c_d", &ParallelKfParams::c_d),
      make("c_d_rate_hz", &ParallelKfParams::c_d_rate_hz),
      make("sigma_gyro_extra_heading_rps", &ParallelKfParams::sigma_gyro_extra_heading_rps),
      {"field_magnitude_ut",
       [](ParallelKfParams& p, const YAML::Node& n) { p.field_magnitude_ut = as_double_or_nan(n); }},
      {"dip_deg", [](ParallelKfParams& p, const YAML::Node& n) { p.dip_deg = as_double_or_nan(n); }},
      make("startup_s", &ParallelKfParams::startup_s),
      make("gyro_current_weight", &ParallelKfParams::gyro_current_weight),
      make("imu_delay_s", &ParallelKfParams::imu_delay_s),
      make("accel_lowpass_tau_s", &ParallelKfParams::accel_lowpass_tau_s),
      make("bias_estimation", &ParallelKfParams::bias_estimation),
      make("rest_gyro_max_rps", &ParallelKfParams::rest_gyro_max_rps),
      make("rest_accel_max_mps2", &ParallelKfParams::rest_accel_max_mps2),
      make("rest_min_s", &ParallelKfParams::rest_min_s),
      make("rest_filter_tau_s", &ParallelKfParams::rest_filter_tau_s),
      make("bias_sigma_init_rps", &ParallelKfParams::bias_sigma_init_rps),
      make("bias_sigma_rest_rps", &ParallelKfParams::bias_sigma_rest_rps),
      make("bias_drift_rps", &ParallelKfParams::bias_drift_rps),
      make("bias_forgetting_time_s", &ParallelKfParams::bias_forgetting_time_s),
      make("motion_bias_sigma_rps", &ParallelKfParams::motion_bias_sigma_rps),
      make("motion_bias_clip_rps", &ParallelKfParams::motion_bias_clip_rps),
      make("motion_gyro_scale_error", &ParallelKfParams::motion_gyro_scale_error),
      make("max_bias_rps", &ParallelKfParams::max_bias_rps),
      make("mag_gating", &ParallelKfParams::mag_gating),
      make("mag_norm_tol", &ParallelKfParams::mag_norm_tol),
      make("mag_dip_tol_deg", &ParallelKfParams::mag_dip_tol_deg),
      make("mag_reference_tau_s", &ParallelKfParams::mag_reference_tau_s),
      make("mag_reacquire_s", &ParallelKfParams::mag_reacquire_s),
      make("mag_reacquire_tol", &ParallelKfParams::mag_reacquire_tol),
      make("mag_max_reject_s", &ParallelKfParams::mag_max_reject_s),
      make("mag_soft_weight", &ParallelKfParams::mag_soft_weight),
      make("share_tilt_correction", &ParallelKfParams::share_tilt_correction),
      make("accel_lowpass_order", &ParallelKfParams::accel_lowpass_order),
      make("motion_bias_heading", &ParallelKfParams::motion_bias_heading),
      {"use_magnetometer",
       [](ParallelKfParams& p, const YAML::Node& n) { p.use_magnetometer = read_magnetometer_use(n); }},
      make_limits("min_accel_norm_mps2", &SampleLimits::min_accel_norm_mps2),
      make_limits("min_mag_norm_ut", &SampleLimits::min_mag_norm_ut),
      make_limits("max_gyro_rps", &SampleLimits::max_gyro_rps),
      make_limits("max_accel_mps2", &SampleLimits::max_accel_mps2),
      make_limits("max_mag_ut", &SampleLimits::max_mag_ut),
      make_limits("max_dt_s", &SampleLimits::max_dt_s),
  };
  return f;
}

void apply(ParallelKfParams& p, const YAML::Node& node, const std::string& prefix,
           const std::string& path) {
  for (const auto& kv : node) {
    const std::string key = prefix + kv.first.as<std::string>();
    if (key == "preset") {
      continue;
    }
    if (kv.second.IsMap()) {
      apply(p, kv.second, key + ".", path);
      continue;
    }
    const Field* found = nullptr;
    for (const auto& f : fields()) {
      if (f.name == key) {
        found = &f;
        break;
      }
    }
    if (found == nullptr) {
      std::string known;
      for (const auto& f : fields()) {
        known += (known.empty() ? "" : ", ") + f.name;
      }
      throw std::runtime_error(path + ": unknown parallel_kf key '" + key + "' (known: preset, " +
                               known + ")");
    }
    try {
      found->set(p, kv.second);
    } catch (const YAML::Exception& e) {
      throw std::runtime_error(path + ": key '" + key + "': " + e.what());
    }
  }
}

}  // namespace

ParallelKfParams load_parallel_kf_params(const std::string& path, const ParallelKfParams& base) {
  YAML::Node root;
  try {
    root = load_yaml_file(path, "parallel_kf config");
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot read parallel_kf config '" + path + "': " + e.what());
  }
  if (root["parallel_kf"]) {
    root = root["parallel_kf"];
  }
  if (!root.IsMap()) {
    throw std::runtime_error(path + ": expected a map of parallel_kf parameters");
  }
  ParallelKfParams p = base;
  if (root["preset"]) {
    try {
      p = ParallelKfParams::named(root["preset"].as<std::string>());
    } catch (const std::exception& e) {
      throw std::runtime_error(path + ": preset: " + e.what());
    }
  }
  apply(p, root, "", path);
  validate_loaded(p, path);
  return p;
}

}  // namespace poise
