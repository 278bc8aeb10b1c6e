// YAML loading of VehicleParams (config/filters/vehicle.yaml). Every key is optional (the C++
// defaults apply); unknown keys and bad values are startup errors naming the file and the key.
#include "poise/vehicle/vehicle_estimator.h"

#include "poise/core/params_check.h"
#include "poise/core/yaml_params.h"

#include <yaml-cpp/yaml.h>

#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace poise {

VehicleParams load_vehicle_params(const std::string& path) {
  const YAML::Node root = load_yaml_file(path, "vehicle estimator configuration");
  VehicleParams p;
  YamlParamReader r(root, path, "", "config/filters/vehicle.yaml");
  std::string mode = to_string(p.mode);
  r.get("mode", mode);
  if (!parse_vehicle_mode(mode, p.mode)) {
    r.fail("mode", "must be one of switched, triad, ekf (got '" + mode + "')");
  }
  r.get("gravity_mps2", p.gravity_mps2);
  r.get("max_dt_s", p.max_dt_s);
  r.get("mag_norm_tolerance", p.mag_norm_tolerance);
  YAML::Node use_mag;
  r.get("use_magnetometer", use_mag);
  if (!use_mag.IsNull()) {  // given
    try {
      p.use_magnetometer = read_magnetometer_use(use_mag);
    } catch (const YAML::Exception&) {
      r.fail("use_magnetometer", "must be auto, true or false (got '" + YAML::Dump(use_mag) + "')");
    }
  }
  {
    YamlParamReader limits = r.child("limits");
    limits.get("max_yaw_rate_rps", p.max_yaw_rate_rps);
    limits.get("max_accel_mps2", p.max_accel_mps2);
    limits.get("max_mag_ut", p.max_mag_ut);
    limits.finish();
  }
  std::vector<double> h = {p.mag_world_ut.x(), p.mag_world_ut.y(), p.mag_world_ut.z()};
  r.get("mag_world_ut", h);
  if (h.size() != 3) {
    r.fail("mag_world_ut", "must be a list of 3 numbers [east, north, up] in uT");
  }
  p.mag_world_ut = Eigen::Vector3d(h[0], h[1], h[2]);

  YamlParamReader m = r.child("model");
  m.get("i_x_kgm2", p.model.i_x_kgm2);
  m.get("i_y_kgm2", p.model.i_y_kgm2);
  m.get("k_x_nm_per_rad", p.model.k_x_nm_per_rad);
  m.get("k_y_nm_per_rad", p.model.k_y_nm_per_rad);
  m.get("b_x_nms_per_rad", p.model.b_x_nms_per_rad);
  m.get("b_y_nms_per_rad", p.model.b_y_nms_per_rad);
  m.get("m_s_kg", p.model.m_s_kg);
  m.get("h_s_m", p.model.h_s_m);
  m.finish();

  YamlParamReader sw = r.child("switching");
  sw.get("static_yaw_rate_max_rps", p.static_yaw_rate_max_rps);
  sw.get("static_speed_max_mps", p.static_speed_max_mps);
  sw.get("static_average", p.static_average);
  sw.finish();

  YamlParamReader ekf = r.child("ekf");
  ekf.get("q_roll_rad2_per_s", p.q_roll_rad2_per_s);
  ekf.get("q_pitch_rad2_per_s", p.q_pitch_rad2_per_s);
  ekf.get("q_yaw_rad2_per_s", p.q_yaw_rad2_per_s);
  std::vector<double> rm = {p.r_mag_ut2.x(), p.r_mag_ut2.y(), p.r_mag_ut2.z()};
  ekf.get("r_mag_ut2", rm);
  if (rm.size() != 3) {
    ekf.fail("ekf.r_mag_ut2", "must be a list of 3 variances [R_x, R_y, R_z] in uT^2");
  }
  p.r_mag_ut2 = Eigen::Vector3d(rm[0], rm[1], rm[2]);
  ekf.get("initial_var_angle_rad2", p.initial_var_angle_rad2);
  ekf.get("initial_var_rate_rad2ps2", p.initial_var_rate_rad2ps2);
  ekf.finish();
  r.finish();

  validate_loaded(p, path);
  return p;
}

}  // namespace poise
