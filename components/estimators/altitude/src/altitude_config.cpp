// YAML loading of AltitudeParams (config/filters/altitude.yaml). Every key is optional (the C++
// defaults apply); unknown keys and bad values are startup errors naming the file and the key.
#include "poise/altitude/altitude_filter.h"

#include "poise/core/params_check.h"
#include "poise/core/yaml_params.h"

#include <yaml-cpp/yaml.h>

#include <set>
#include <stdexcept>
#include <string>

namespace poise {

AltitudeParams load_altitude_params(const std::string& path) {
  const YAML::Node root = load_yaml_file(path, "altitude filter configuration");
  AltitudeParams p;
  YamlParamReader r(root, path, "", "config/filters/altitude.yaml");
  std::string method = to_string(p.method);
  r.get("method", method);
  if (!parse_altitude_method(method, p.method)) {
    r.fail("method", "must be one of two_step_kf, cf_zupt, pi_cf_zupt, pi_cf (got '" + method + "')");
  }
  r.get("gravity_mps2", p.gravity_mps2);
  r.get("max_dt_s", p.max_dt_s);

  YamlParamReader limits = r.child("limits");
  limits.get("max_gyro_rps", p.max_gyro_rps);
  limits.get("max_accel_mps2", p.max_accel_mps2);
  limits.finish();

  YamlParamReader baro = r.child("barometer");
  baro.get("reference_pressure_pa", p.reference_pressure_pa);
  baro.get("paper_rounded_constants", p.paper_rounded_constants);
  baro.get("min_pressure_pa", p.min_pressure_pa);
  baro.get("max_pressure_pa", p.max_pressure_pa);
  baro.get("max_baro_age_s", p.max_baro_age_s);
  baro.finish();

  YamlParamReader cf = r.child("cf");
  std::string gains = to_string(p.gains);
  cf.get("gains", gains);
  if (!parse_cf_gains(gains, p.gains)) {
    cf.fail("cf.gains", "must be 'paper' or 'higgins' (got '" + gains + "')");
  }
  cf.get("sigma_acc_mps2", p.sigma_acc_mps2);
  cf.get("sigma_baro_m", p.sigma_baro_m);
  cf.get("k_i", p.k_i);
  cf.get("integral_velocity_only", p.integral_velocity_only);
  cf.get("integral_time_scaled", p.integral_time_scaled);
  cf.finish();

  YamlParamReader zupt = r.child("zupt");
  zupt.get("gyro_max_rps", p.zupt_gyro_max_rps);
  zupt.get("accel_dev_max_mps2", p.zupt_accel_dev_max_mps2);
  zupt.get("window_s", p.zupt_window_s);
  zupt.finish();

  YamlParamReader tilt = r.child("tilt");
  tilt.get("sigma_gyro_rps", p.tilt.sigma_gyro_rps);
  tilt.get("sigma_accel_mps2", p.tilt.sigma_accel_mps2);
  tilt.get("c_a", p.tilt.c_a);
  tilt.get("c_a_rate_hz", p.tilt.c_a_rate_hz);
  tilt.get("exact_rotation", p.tilt.exact_rotation);
  tilt.get("renormalize", p.tilt.renormalize);
  tilt.get("sigma_gyro_extra_rps", p.tilt.sigma_gyro_extra_rps);
  tilt.finish();
  r.finish();

  validate_loaded(p, path);
  return p;
}

}  // namespace poise
