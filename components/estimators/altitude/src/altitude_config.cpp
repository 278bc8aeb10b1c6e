// YAML loading of AltitudeParams (config/filters/altitude.yaml), the one loader shape
// (poise/core/yaml_params.h). Every key is optional (the C++ defaults apply); unknown keys and
// bad values are startup errors naming the file and the key.
#include "poise/altitude/altitude_filter.h"

#include "poise/core/yaml_params.h"

#include <string>

namespace poise {

AltitudeParams load_altitude_params(const std::string& path) {
  return load_params_file(path, "altitude filter configuration", "", AltitudeParams{},
                          [](YamlParamReader& r, AltitudeParams& p) {
    r.get_enum("method", p.method,
               {AltitudeMethod::kTwoStepKf, AltitudeMethod::kCfZupt, AltitudeMethod::kPiCfZupt, AltitudeMethod::kPiCf});
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
    cf.get_enum("gains", p.gains, {CfGains::kPaper, CfGains::kHiggins});
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
    p.tilt.read(tilt);
    tilt.finish();
  });
}

}  // namespace poise
