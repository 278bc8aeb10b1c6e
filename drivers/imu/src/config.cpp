#include "poise/imu/config.h"
#include "poise/core/yaml_params.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>

namespace poise::imu {
namespace {

class Reader {
 public:
  explicit Reader(std::string origin) : origin_(std::move(origin)) {}

  [[noreturn]] void fail(const std::string& key, const std::string& what) const {
    throw ConfigError(origin_ + ": " + key + ": " + what);
  }

  /// Rejects keys of `node` not in `allowed` (typos must not pass silently).
  void only(const YAML::Node& node, const std::string& path, std::set<std::string> allowed) const {
    if (!node) return;
    if (!node.IsMap()) fail(path, "must be a mapping");
    for (const auto& kv : node) {
      const auto key = kv.first.as<std::string>();
      if (allowed.count(key) == 0) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        fail(path.empty() ? key : path + "." + key, "unknown key (expected one of: " + list + ")");
      }
    }
  }

  void number(const YAML::Node& node, const std::string& path, double lo, double hi,
              double* out) const {
    if (!node) return;
    double v = 0;
    try {
      v = node.as<double>();
    } catch (const YAML::Exception&) {
      fail(path, "must be a number");
    }
    if (!std::isfinite(v) || v < lo || v > hi) {
      std::ostringstream os;
      os << "must be in [" << lo << ", " << hi << "], got " << v;
      fail(path, os.str());
    }
    *out = v;
  }

  void integer(const YAML::Node& node, const std::string& path, long lo, long hi, long* out) const {
    if (!node) return;
    long v = 0;
    try {
      v = node.as<long>();
    } catch (const YAML::Exception&) {
      fail(path, "must be an integer");
    }
    if (v < lo || v > hi) {
      fail(path, "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                     std::to_string(v));
    }
    *out = v;
  }

  void vec3(const YAML::Node& node, const std::string& path, Eigen::Vector3d* out) const {
    if (!node) return;
    if (!node.IsSequence() || node.size() != 3) fail(path, "must be a list of 3 numbers");
    for (std::size_t i = 0; i < 3; ++i) {
      double v = 0;
      number(node[i], path + "[" + std::to_string(i) + "]", -1e9, 1e9, &v);
      (*out)(static_cast<Eigen::Index>(i)) = v;
    }
  }

  void mat3(const YAML::Node& node, const std::string& path, Eigen::Matrix3d* out) const {
    if (!node) return;
    if (!node.IsSequence() || node.size() != 3) fail(path, "must be 3 rows of 3 numbers");
    for (std::size_t r = 0; r < 3; ++r) {
      Eigen::Vector3d row;
      vec3(node[r], path + "[" + std::to_string(r) + "]", &row);
      out->row(static_cast<Eigen::Index>(r)) = row.transpose();
    }
  }

  void text(const YAML::Node& node, const std::string& path, std::string* out) const {
    if (!node) return;
    if (!node.IsScalar()) fail(path, "must be a string");
    *out = node.as<std::string>();
  }

  void axes(const YAML::Node& node, const std::string& path, AxisMap* out) const {
    if (!node) return;
    std::string t;
    text(node, path, &t);
    std::string err;
    if (!AxisMap::parse(t, out, &err)) fail(path, err);
  }

 private:
  std::string origin_;
};

}  // namespace

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
  Reader rd(origin);
  const YAML::Node root = parse_yaml<ConfigError>(yaml_text, origin);
  DriverConfig c;
  if (!root || root.IsNull()) return c;
  rd.only(root, "", {"serial", "protocol", "limits", "raw", "clock", "calibration"});

  const YAML::Node serial = root["serial"];
  rd.only(serial, "serial", {"baud", "reconnect_initial_s", "reconnect_max_s", "tx_correction"});
  if (serial) {
    long baud = c.serial.baud;
    rd.integer(serial["baud"], "serial.baud", 0, 10000000, &baud);
    if (!is_supported_baud(static_cast<int>(baud))) {
      std::string list;
      for (const int b : supported_bauds()) list += (list.empty() ? "" : ", ") + std::to_string(b);
      rd.fail("serial.baud", std::to_string(baud) + " is not supported (use one of " + list + ")");
    }
    c.serial.baud = static_cast<int>(baud);
    rd.number(serial["reconnect_initial_s"], "serial.reconnect_initial_s", 0.01, 60,
              &c.serial.reconnect_initial_s);
    rd.number(serial["reconnect_max_s"], "serial.reconnect_max_s", 0.01, 600,
              &c.serial.reconnect_max_s);
    if (c.serial.reconnect_max_s < c.serial.reconnect_initial_s) {
      rd.fail("serial.reconnect_max_s", "must be >= serial.reconnect_initial_s");
    }
    rd.text(serial["tx_correction"], "serial.tx_correction", &c.serial.tx_correction);
    if (c.serial.tx_correction != "auto" && c.serial.tx_correction != "on" &&
        c.serial.tx_correction != "off") {
      rd.fail("serial.tx_correction", "must be auto, on or off");
    }
  }

  const YAML::Node protocol = root["protocol"];
  rd.only(protocol, "protocol", {"reorder_window", "max_forward_gap", "sensor_latency_s"});
  if (protocol) {
    long v = c.params.sequence.reorder_window;
    rd.integer(protocol["reorder_window"], "protocol.reorder_window", 0, 100000, &v);
    c.params.sequence.reorder_window = static_cast<uint32_t>(v);
    v = c.params.sequence.max_forward_gap;
    rd.integer(protocol["max_forward_gap"], "protocol.max_forward_gap", 1, 1000000000, &v);
    c.params.sequence.max_forward_gap = static_cast<uint32_t>(v);
    rd.number(protocol["sensor_latency_s"], "protocol.sensor_latency_s", 0, 1,
              &c.params.sensor_latency_s);
  }

  const YAML::Node limits = root["limits"];
  rd.only(limits, "limits", {"accel_max_mps2", "gyro_max_rps", "mag_max_ut", "pressure_min_pa",
                             "pressure_max_pa", "temperature_min_c", "temperature_max_c"});
  if (limits) {
    Limits& l = c.params.limits;
    rd.number(limits["accel_max_mps2"], "limits.accel_max_mps2", 1, 10000, &l.accel_max_mps2);
    rd.number(limits["gyro_max_rps"], "limits.gyro_max_rps", 0.1, 1000, &l.gyro_max_rps);
    rd.number(limits["mag_max_ut"], "limits.mag_max_ut", 1, 100000, &l.mag_max_ut);
    rd.number(limits["pressure_min_pa"], "limits.pressure_min_pa", 0, 1e7, &l.pressure_min_pa);
    rd.number(limits["pressure_max_pa"], "limits.pressure_max_pa", 0, 1e7, &l.pressure_max_pa);
    rd.number(limits["temperature_min_c"], "limits.temperature_min_c", -273.15, 1000,
              &l.temperature_min_c);
    rd.number(limits["temperature_max_c"], "limits.temperature_max_c", -273.15, 1000,
              &l.temperature_max_c);
    if (l.pressure_min_pa >= l.pressure_max_pa) {
      rd.fail("limits.pressure_min_pa", "must be < limits.pressure_max_pa");
    }
    if (l.temperature_min_c >= l.temperature_max_c) {
      rd.fail("limits.temperature_min_c", "must be < limits.temperature_max_c");
    }
  }

  const YAML::Node raw = root["raw"];
  rd.only(raw, "raw", {"accel_lsb_per_g", "gyro_lsb_per_dps", "mag_lsb_per_gauss",
                       "temp_lsb_per_c", "temp_offset_c", "g_mps2"});
  if (raw) {
    RawScale& r = c.params.raw;
    rd.number(raw["accel_lsb_per_g"], "raw.accel_lsb_per_g", 1, 1e6, &r.accel_lsb_per_g);
    rd.number(raw["gyro_lsb_per_dps"], "raw.gyro_lsb_per_dps", 0.01, 1e6, &r.gyro_lsb_per_dps);
    rd.number(raw["mag_lsb_per_gauss"], "raw.mag_lsb_per_gauss", 1, 1e6, &r.mag_lsb_per_gauss);
    rd.number(raw["temp_lsb_per_c"], "raw.temp_lsb_per_c", 0.01, 1e6, &r.temp_lsb_per_c);
    rd.number(raw["temp_offset_c"], "raw.temp_offset_c", -100, 200, &r.temp_offset_c);
    rd.number(raw["g_mps2"], "raw.g_mps2", 9.7, 9.9, &r.g_mps2);
  }

  const YAML::Node clock = root["clock"];
  rd.only(clock, "clock", {"block_s", "window_blocks", "max_drift_ppm", "reset_threshold_s", "reanchor_samples"});
  if (clock) {
    ClockSyncParams& k = c.params.clock;
    rd.number(clock["block_s"], "clock.block_s", 0.01, 60, &k.block_s);
    long wb = k.window_blocks;
    rd.integer(clock["window_blocks"], "clock.window_blocks", 2, 10000, &wb);
    k.window_blocks = static_cast<int>(wb);
    rd.number(clock["max_drift_ppm"], "clock.max_drift_ppm", 0, 100000, &k.max_drift_ppm);
    rd.number(clock["reset_threshold_s"], "clock.reset_threshold_s", 0.01, 3600,
              &k.reset_threshold_s);
    long ra = k.reanchor_samples;
    rd.integer(clock["reanchor_samples"], "clock.reanchor_samples", 2, 1000, &ra);
    k.reanchor_samples = static_cast<int>(ra);
  }

  const YAML::Node cal = root["calibration"];
  rd.only(cal, "calibration", {"imu_axes", "mag_axes", "gyro_bias_rps", "gyro_scale",
                               "accel_bias_mps2", "accel_scale", "mag_hard_iron_ut",
                               "mag_soft_iron"});
  if (cal) {
    Calibration& k = c.calibration;
    rd.axes(cal["imu_axes"], "calibration.imu_axes", &k.imu_axes);
    rd.axes(cal["mag_axes"], "calibration.mag_axes", &k.mag_axes);
    rd.vec3(cal["gyro_bias_rps"], "calibration.gyro_bias_rps", &k.gyro_bias_rps);
    rd.vec3(cal["gyro_scale"], "calibration.gyro_scale", &k.gyro_scale);
    rd.vec3(cal["accel_bias_mps2"], "calibration.accel_bias_mps2", &k.accel_bias_mps2);
    rd.vec3(cal["accel_scale"], "calibration.accel_scale", &k.accel_scale);
    rd.vec3(cal["mag_hard_iron_ut"], "calibration.mag_hard_iron_ut", &k.mag_hard_iron_ut);
    rd.mat3(cal["mag_soft_iron"], "calibration.mag_soft_iron", &k.mag_soft_iron);
    const std::string err = k.validate();
    if (!err.empty()) rd.fail("calibration", err);
  }
  return c;
}

DriverConfig load_driver_config(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    throw ConfigError(path + ": cannot read the IMU driver configuration (does the file exist? "
                             "`poise calibrate imu` writes one)");
  }
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_driver_config(ss.str(), path);
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
