// Driver configuration file (YAML, config/drivers/imu.yaml): load, validate, write.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include "poise/imu/calibration.h"
#include "poise/imu/driver.h"
#include "poise/imu/serial_port.h"  // SerialSettings

namespace poise::imu {

/// A configuration file that is missing, unreadable or invalid; what() names the file and key.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct DriverConfig {
  SerialSettings serial;
  DriverParams params;
  Calibration calibration;
};

/// Baud rates the serial port accepts (9600 .. 1000000).
const std::vector<int>& supported_bauds();
bool is_supported_baud(int baud);

/// Parses YAML text; `origin` names the source in messages. Missing keys keep their defaults;
/// unknown keys and invalid values are errors.
DriverConfig parse_driver_config(const std::string& yaml_text, const std::string& origin);
/// Loads a file; throws ConfigError("<path>: ...") if it is missing or invalid.
DriverConfig load_driver_config(const std::string& path);
/// Full YAML for a configuration (every key, with comments in the header).
std::string to_yaml(const DriverConfig& config);
/// Writes to_yaml() atomically (temp file + rename); throws ConfigError on I/O failure.
void save_driver_config(const DriverConfig& config, const std::string& path);

}  // namespace poise::imu
