#include "poise/nodes/imu_delay.h"

#include "poise/core/yaml_params.h"

#include <cmath>
#include <cstdio>

namespace poise::nodes {

bool ImuDelayChoice::offer(double delay_s, const std::string& what) {
  if (explicit_ || (published_ && delay_s == in_use_s_ && what == what_)) {
    return false;
  }
  const bool changed = !published_ || delay_s != in_use_s_;
  in_use_s_ = delay_s;
  published_ = true;
  what_ = what;
  return changed;
}

std::string ImuDelayChoice::describe() const {
  char buf[64];
  if (std::isnan(in_use_s_)) {  // the filter's own default for an unknown delay
    std::snprintf(buf, sizeof buf, "imu_delay_s not known (half a sample assumed)");
  } else {
    std::snprintf(buf, sizeof buf, "imu_delay_s %.6f s", in_use_s_);
  }
  std::string s = buf;
  if (explicit_) {
    return s + " (configured; a published delay is ignored)";
  }
  if (published_) {
    return s + " (published by the IMU driver: " + what_ + ")";
  }
  return s + " (default: nothing configured, nothing published on imu_info yet)";
}

bool imu_delay_configured(const runtime::ComponentSpec& spec, const std::string& filter_file,
                          const std::string& section) {
  if (spec.params && spec.params.IsMap() && spec.params["imu_delay_s"]) {
    return true;
  }
  if (filter_file.empty()) {
    return false;
  }
  // The file was loaded and checked already; here only whether the key is present.
  const YAML::Node root = load_yaml_file(filter_file, "filter file");
  if (!root.IsMap()) {
    return false;
  }
  if (root["imu_delay_s"] || root[section + ".imu_delay_s"]) {
    return true;
  }
  const YAML::Node sec = root[section];
  return sec && sec.IsMap() && sec["imu_delay_s"];
}

}  // namespace poise::nodes
