// The test oracle of the msg::SOURCE_* bit each published source name stands for (estimates.idl),
// written out by hand from the wire names: independent of the nodes' typed mapping
// (poise/nodes/reports.h source_bit), which the tests check against it.
#pragma once

#include <poise/msg/estimates.h>

#include <cstdint>
#include <map>
#include <string>

namespace poise::testing {

inline const std::map<std::string, uint32_t>& expected_source_bits() {
  static const std::map<std::string, uint32_t> bits = {
      {"gyro", msg::SOURCE_GYRO},
      {"yaw_rate", msg::SOURCE_GYRO},
      {"accel", msg::SOURCE_ACCEL},
      {"accel_tilt", msg::SOURCE_ACCEL},
      {"mag", msg::SOURCE_MAG},
      {"mag_heading", msg::SOURCE_MAG},
      {"imu_quat", msg::SOURCE_IMU_QUAT},
      {"vision_attitude", msg::SOURCE_VISION},
      {"vision_position", msg::SOURCE_VISION},
      {"baro", msg::SOURCE_BARO},
      {"speed", msg::SOURCE_SPEED},
      {"zupt", 0U},       // pseudo-measurements of a rest detector: no sensor bit
      {"zero_rate", 0U},
  };
  return bits;
}

}  // namespace poise::testing
