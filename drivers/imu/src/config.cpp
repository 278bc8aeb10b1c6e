#include "poise/imu/config.h"

#include "poise/core/yaml_params.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <type_traits>
#include <utility>

namespace poise::imu {
const std::vector<int>& supported_bauds() {
  static const std::vector<int> bauds{9600,   19200,  38400,  57600,  115200, 230400,
                                      460800, 500000, 576000, 921600, 1000000};
  return bauds;
}

bool is_supported_baud(int baud) {
  const auto& b = supported_bauds();
  return std::find(b.begin(), b.end(), baud) != b.end();
}

// not split: one table of keys read in the file's documented order, each line a key and its unit.
DriverConfig parse_driver_config(const std::string& yaml_text, const std::string& origin) {
  using Reader = BasicYamlParamReader<ConfigError>;
  DriverConfig c;
  Reader root(parse_yaml<ConfigError>(yaml_text, origin), origin);
  // Integers are read as long and range-checked before they are narrowed.
  const auto integer = [](Reader& r, const char* key, auto& field, long lo, long hi) {
    long v = static_cast<long>(field);
    r.get_in(key, v, lo, hi);
    field = static_cast<std::remove_reference_t<decltype(field)>>(v);
  };

  Reader serial = root.child("serial");
  integer(serial, "baud", c.serial.baud, 0, 10000000);
  if (!is_supported_baud(c.serial.baud)) {
    std::string list;
    for (const int b : supported_bauds()) list += (list.empty() ? "" : ", ") + std::to_string(b);
    serial.fail("baud", std::to_string(c.serial.baud) + " is not supported (use one of " + list + ")");
  }
  serial.get_in("reconnect_initial_s", c.serial.reconnect_initial_s, 0.01, 60.0);
  serial.get_in("reconnect_max_s", c.serial.reconnect_max_s, 0.01, 600.0);
  if (c.serial.reconnect_max_s < c.serial.reconnect_initial_s) {
    serial.fail("reconnect_max_s", "must be >= serial.reconnect_initial_s");
  }
  serial.get("tx_correction", c.serial.tx_correction);
  if (c.serial.tx_correction != "auto" && c.serial.tx_correction != "on" && c.serial.tx_correction != "off") {
    serial.fail("tx_correction", "must be auto, on or off");
  }
  serial.finish();

  Reader protocol = root.child("protocol");
  integer(protocol, "reorder_window", c.params.sequence.reorder_window, 0, 100000);
  integer(protocol, "max_forward_gap", c.params.sequence.max_forward_gap, 1, 1000000000);
  protocol.get_in("sensor_latency_s", c.params.sensor_latency_s, 0.0, 1.0);
  protocol.finish();

  Reader limits = root.child("limits");
  Limits& l = c.params.limits;
  limits.get_in("accel_max_mps2", l.accel_max_mps2, 1.0, 10000.0);
  limits.get_in("gyro_max_rps", l.gyro_max_rps, 0.1, 1000.0);
  limits.get_in("mag_max_ut", l.mag_max_ut, 1.0, 100000.0);
  limits.get_in("pressure_min_pa", l.pressure_min_pa, 0.0, 1e7);
  limits.get_in("pressure_max_pa", l.pressure_max_pa, 0.0, 1e7);
  limits.get_in("temperature_min_c", l.temperature_min_c, -273.15, 1000.0);
  limits.get_in("temperature_max_c", l.temperature_max_c, -273.15, 1000.0);
  if (l.pressure_min_pa >= l.pressure_max_pa) {
    limits.fail("pressure_min_pa", "must be < limits.pressure_max_pa");
  }
  if (l.temperature_min_c >= l.temperature_max_c) {
    limits.fail("temperature_min_c", "must be < limits.temperature_max_c");
  }
  limits.finish();

  Reader raw = root.child("raw");
  RawScale& rs = c.params.raw;
  raw.get_in("accel_lsb_per_g", rs.accel_lsb_per_g, 1.0, 1e6);
  raw.get_in("gyro_lsb_per_dps", rs.gyro_lsb_per_dps, 0.01, 1e6);
  raw.get_in("mag_lsb_per_gauss", rs.mag_lsb_per_gauss, 1.0, 1e6);
  raw.get_in("temp_lsb_per_c", rs.temp_lsb_per_c, 0.01, 1e6);
  raw.get_in("temp_offset_c", rs.temp_offset_c, -100.0, 200.0);
  raw.get_in("g_mps2", rs.g_mps2, 9.7, 9.9);
  raw.finish();

  Reader clock = root.child("clock");
  ClockSyncParams& k = c.params.clock;
  clock.get_in("block_s", k.block_s, 0.01, 60.0);
  integer(clock, "window_blocks", k.window_blocks, 2, 10000);
  clock.get_in("max_drift_ppm", k.max_drift_ppm, 0.0, 100000.0);
  clock.get_in("reset_threshold_s", k.reset_threshold_s, 0.01, 3600.0);
  integer(clock, "reanchor_samples", k.reanchor_samples, 2, 1000);
  clock.finish();

  Reader cal = root.child("calibration");
  Calibration& m = c.calibration;
  for (auto [key, axes] : {std::pair<const char*, AxisMap*>{"imu_axes", &m.imu_axes}, {"mag_axes", &m.mag_axes}}) {
    cal.get_with(key, [axes = axes](const YAML::Node& n) {
      std::string err;
      if (!n.IsScalar() || !AxisMap::parse(n.Scalar(), axes, &err)) {
        throw std::invalid_argument(err.empty() ? "must be a string such as \"+x,+y,+z\"" : err);
      }
    });
  }
  constexpr double kVectorBound = 1e9;  // any calibration number, however wrong, stays finite
  cal.get_in("gyro_bias_rps", m.gyro_bias_rps, -kVectorBound, kVectorBound);
  cal.get_in("gyro_scale", m.gyro_scale, -kVectorBound, kVectorBound);
  cal.get_in("accel_bias_mps2", m.accel_bias_mps2, -kVectorBound, kVectorBound);
  cal.get_in("accel_scale", m.accel_scale, -kVectorBound, kVectorBound);
  cal.get_in("mag_hard_iron_ut", m.mag_hard_iron_ut, -kVectorBound, kVectorBound);
  cal.get_in("mag_soft_iron", m.mag_soft_iron, -kVectorBound, kVectorBound);
  const bool calibration_given = root.has("calibration");
  cal.finish();
  if (calibration_given) {
    const std::string err = m.validate();
    if (!err.empty()) root.fail("calibration", err);
  }
  root.finish();
  return c;
}

DriverConfig load_driver_config(const std::string& path) {
  return parse_driver_config(read_yaml_text<ConfigError>(path, path + ": cannot read the IMU driver configuration (does "
                                                                      "the file exist? `poise calibrate imu` writes one)"),
                             path);
}

std::string to_yaml(const DriverConfig& c) {
  const auto v3 = [](const Eigen::Vector3d& v) {
    char b[128];
    std::snprintf(b, sizeof b, "[%.9g, %.9g, %.9g]", v.x(), v.y(), v.z());
    return std::string(b);
  };
  std::ostringstream o;
  o << "# poise serial IMU driver configuration (docs/SERIAL_PROTOCOL.md).\n"
    << "serial:\n"
    << "  baud: " << c.serial.baud << "\n"
    << "  reconnect_initial_s: " << c.serial.reconnect_initial_s << "\n"
    << "  reconnect_max_s: " << c.serial.reconnect_max_s << "\n"
    << "  tx_correction: " << c.serial.tx_correction << "\n"
    << "protocol:\n"
    << "  reorder_window: " << c.params.sequence.reorder_window << "\n"
    << "  max_forward_gap: " << c.params.sequence.max_forward_gap << "\n"
    << "  sensor_latency_s: " << c.params.sensor_latency_s << "\n"
    << "limits:\n"
    << "  accel_max_mps2: " << c.params.limits.accel_max_mps2 << "\n"
    << "  gyro_max_rps: " << c.params.limits.gyro_max_rps << "\n"
    << "  mag_max_ut: " << c.params.limits.mag_max_ut << "\n"
    << "  pressure_min_pa: " << c.params.limits.pressure_min_pa << "\n"
    << "  pressure_max_pa: " << c.params.limits.pressure_max_pa << "\n"
    << "  temperature_min_c: " << c.params.limits.temperature_min_c << "\n"
    << "  temperature_max_c: " << c.params.limits.temperature_max_c << "\n"
    << "raw:\n"
    << "  accel_lsb_per_g: " << c.params.raw.accel_lsb_per_g << "\n"
    << "  gyro_lsb_per_dps: " << c.params.raw.gyro_lsb_per_dps << "\n"
    << "  mag_lsb_per_gauss: " << c.params.raw.mag_lsb_per_gauss << "\n"
    << "  temp_lsb_per_c: " << c.params.raw.temp_lsb_per_c << "\n"
    << "  temp_offset_c: " << c.params.raw.temp_offset_c << "\n"
    << "  g_mps2: " << c.params.raw.g_mps2 << "\n"
    << "clock:\n"
    << "  block_s: " << c.params.clock.block_s << "\n"
    << "  window_blocks: " << c.params.clock.window_blocks << "\n"
    << "  max_drift_ppm: " << c.params.clock.max_drift_ppm << "\n"
    << "  reset_threshold_s: " << c.params.clock.reset_threshold_s << "\n"
    << "  reanchor_samples: " << c.params.clock.reanchor_samples << "\n"
    << "calibration:\n"
    << "  imu_axes: \"" << c.calibration.imu_axes.to_string() << "\"\n"
    << "  mag_axes: \"" << c.calibration.mag_axes.to_string() << "\"\n"
    << "  gyro_bias_rps: " << v3(c.calibration.gyro_bias_rps) << "\n"
    << "  gyro_scale: " << v3(c.calibration.gyro_scale) << "\n"
    << "  accel_bias_mps2: " << v3(c.calibration.accel_bias_mps2) << "\n"
    << "  accel_scale: " << v3(c.calibration.accel_scale) << "\n"
    << "  mag_hard_iron_ut: " << v3(c.calibration.mag_hard_iron_ut) << "\n"
    << "  mag_soft_iron:\n";
  for (Eigen::Index r = 0; r < 3; ++r) {
    o << "    - " << v3(c.calibration.mag_soft_iron.row(r).transpose()) << "\n";
  }
  return o.str();
}

void save_driver_config(const DriverConfig& config, const std::string& path) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw ConfigError(path + ": cannot write (check the directory exists and is writable)");
    out << to_yaml(config);
    if (!out) throw ConfigError(path + ": write failed");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw ConfigError(path + ": cannot replace the file");
  }
}

}  // namespace poise::imu
