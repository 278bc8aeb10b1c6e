// YAML loading of VehicleParams (config/filters/vehicle.yaml), the one loader shape
// (poise/core/yaml_params.h). Every key is optional (the C++ defaults apply); unknown keys and
// bad values are startup errors naming the file and the key.
#include "poise/vehicle/vehicle_estimator.h"

#include "poise/core/yaml_params.h"

#include <string>

namespace poise {

VehicleParams load_vehicle_params(const std::string& path) {
  return load_params_file(path, "vehicle estimator configuration", "", VehicleParams{},
                          [](YamlParamReader& r, VehicleParams& p) {
    r.get_enum("mode", p.mode, {VehicleMode::kSwitched, VehicleMode::kTriad, VehicleMode::kEkf});
    r.get("gravity_mps2", p.gravity_mps2);
    r.get("max_dt_s", p.max_dt_s);
    r.get("mag_norm_tolerance", p.mag_norm_tolerance);
    read_magnetometer_use(r, p.use_magnetometer);
    r.get("mag_world_ut", p.mag_world_ut);  // [east, north, up], uT

    YamlParamReader limits = r.child("limits");
    limits.get("max_yaw_rate_rps", p.max_yaw_rate_rps);
    limits.get("max_accel_mps2", p.max_accel_mps2);
    limits.get("max_mag_ut", p.max_mag_ut);
    limits.finish();

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
    ekf.get("r_mag_ut2", p.r_mag_ut2);  // [R_x, R_y, R_z], uT^2
    ekf.get("initial_var_angle_rad2", p.initial_var_angle_rad2);
    ekf.get("initial_var_rate_rad2ps2", p.initial_var_rate_rad2ps2);
    ekf.finish();
  });
}

}  // namespace poise
