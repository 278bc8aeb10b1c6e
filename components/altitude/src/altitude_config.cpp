// YAML loading of AltitudeParams (config/filters/altitude.yaml). Every key is optional (the C++
// defaults apply); unknown keys and bad values are startup errors naming the file and the key.
#include "poise/altitude/altitude_filter.h"

#include <yaml-cpp/yaml.h>

#include <set>
#include <stdexcept>
#include <string>

namespace poise {
namespace {

class Reader {
 public:
  Reader(const YAML::Node& node, std::string path, std::string prefix)
      : node_(node), path_(std::move(path)), prefix_(std::move(prefix)) {
    present_ = node_.IsDefined() && !node_.IsNull();
    if (present_ && !node_.IsMap()) {
      fail(prefix_.empty() ? "the document" : prefix_, "must be a mapping");
    }
  }

  template <typename T>
  void get(const std::string& key, T& out) {
    known_.insert(key);
    if (!present_) {
      return;
    }
    const YAML::Node v = static_cast<const YAML::Node&>(node_)[key];
    if (!v.IsDefined() || v.IsNull()) {
      return;
    }
    try {
      out = v.as<T>();
    } catch (const YAML::Exception&) {
      fail(name(key), "has the wrong type");
    }
  }

  Reader child(const std::string& key) {
    known_.insert(key);
    if (!present_) {
      return Reader(YAML::Node(), path_, name(key));
    }
    return Reader(static_cast<const YAML::Node&>(node_)[key], path_, name(key));
  }

  void finish() const {
    if (!present_) {
      return;
    }
    for (const auto& kv : node_) {
      const auto key = kv.first.as<std::string>();
      if (known_.count(key) == 0) {
        fail(name(key), "is not a known key (check the spelling against config/filters/altitude.yaml)");
      }
    }
  }

  [[noreturn]] void fail(const std::string& key, const std::string& what) const {
    throw std::runtime_error(path_ + ": " + key + " " + what);
  }
  [[nodiscard]] std::string name(const std::string& key) const {
    return prefix_.empty() ? key : prefix_ + "." + key;
  }

 private:
  YAML::Node node_;
  std::string path_;
  std::string prefix_;
  std::set<std::string> known_;
  bool present_ = false;
};

}  // namespace

AltitudeParams load_altitude_params(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw std::runtime_error(path + ": cannot open the altitude filter configuration");
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(path + ": invalid YAML: " + e.what());
  }
  AltitudeParams p;
  Reader r(root, path, "");
  std::string method = to_string(p.method);
  r.get("method", method);
  if (!parse_altitude_method(method, p.method)) {
    r.fail("method", "must be one of two_step_kf, cf_zupt, pi_cf_zupt, pi_cf (got '" + method + "')");
  }
  r.get("gravity_mps2", p.gravity_mps2);
  r.get("max_dt_s", p.max_dt_s);

  Reader baro = r.child("barometer");
  baro.get("reference_pressure_pa", p.reference_pressure_pa);
  baro.get("paper_rounded_constants", p.paper_rounded_constants);
  baro.get("min_pressure_pa", p.min_pressure_pa);
  baro.get("max_pressure_pa", p.max_pressure_pa);
  baro.get("max_baro_age_s", p.max_baro_age_s);
  baro.finish();

  Reader cf = r.child("cf");
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

  Reader zupt = r.child("zupt");
  zupt.get("gyro_max_rps", p.zupt_gyro_max_rps);
  zupt.get("accel_dev_max_mps2", p.zupt_accel_dev_max_mps2);
  zupt.get("window_s", p.zupt_window_s);
  zupt.finish();

  Reader tilt = r.child("tilt");
  tilt.get("sigma_gyro_rps", p.tilt.sigma_gyro_rps);
  tilt.get("sigma_accel_mps2", p.tilt.sigma_accel_mps2);
  tilt.get("c_a", p.tilt.c_a);
  tilt.get("c_a_rate_hz", p.tilt.c_a_rate_hz);
  tilt.get("exact_rotation", p.tilt.exact_rotation);
  tilt.get("renormalize", p.tilt.renormalize);
  tilt.get("sigma_gyro_extra_rps", p.tilt.sigma_gyro_extra_rps);
  tilt.finish();
  r.finish();

  const std::string problems = p.validate();
  if (!problems.empty()) {
    throw std::runtime_error(path + ": " + problems);
  }
  return p;
}

}  // namespace poise
