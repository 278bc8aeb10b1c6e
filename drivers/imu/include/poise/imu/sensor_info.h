// What a serial IMU says about itself: the `$INF` line (docs/SERIAL_PROTOCOL.md "Sensor info")
// resolved to the sensor's group delays, and the table of the one chip the driver knows.
//
// The MPU-6000/6050's digital low-pass filter (register 26 CONFIG, DLPF_CFG) delays both the
// accelerometer and the gyroscope; its datasheet gives the delay per setting:
//   InvenSense, "MPU-6000 and MPU-6050 Register Map and Descriptions", RM-MPU-6000A-00 rev 4.2
//   (2013), section 4.3 "Register 26 - Configuration", DLPF_CFG table.
// A filter that knows the delay predicts its output over it (imu_delay_s); see
// "The IMU's delay (imu_delay_s)" (docs/ESTIMATORS.md) for how to find the figure for another
// sensor.
#pragma once

#include "poise/imu/protocol.h"

#include <array>
#include <cstdint>
#include <optional>
#include <string>

namespace poise::imu {

/// One row of the MPU6050 DLPF_CFG table (register map rev 4.2, register 26).
struct Mpu6050Dlpf {
  int dlpf_cfg;
  double accel_bandwidth_hz;
  double accel_delay_ms;
  double gyro_bandwidth_hz;
  double gyro_delay_ms;
  double gyro_output_rate_khz;  ///< Fs of the gyroscope (the accelerometer's is 1 kHz throughout)
};

/// The whole table: settings 0..6 (7 is reserved: no figures, refused).
inline constexpr std::array<Mpu6050Dlpf, 7> kMpu6050Dlpf{{
    {0, 260.0, 0.0, 256.0, 0.98, 8.0},
    {1, 184.0, 2.0, 188.0, 1.9, 1.0},
    {2, 94.0, 3.0, 98.0, 2.8, 1.0},
    {3, 44.0, 4.9, 42.0, 4.8, 1.0},
    {4, 21.0, 8.5, 20.0, 8.3, 1.0},
    {5, 10.0, 13.8, 10.0, 13.4, 1.0},
    {6, 5.0, 19.0, 5.0, 18.6, 1.0},
}};

/// The row of a DLPF_CFG setting; nullptr for 7 (reserved) and anything outside 0..7.
const Mpu6050Dlpf* mpu6050_dlpf(int dlpf_cfg);

/// A sensor's delays as the driver publishes them (msg::ImuSensorInfo).
struct SensorDelay {
  std::string chip;
  int32_t setting = -1;        ///< the chip's low-pass setting; -1 unknown
  double accel_delay_s = 0.0;
  double gyro_delay_s = 0.0;
  /// "table" (the driver's datasheet table for the chip and setting) or "sensor" (the line's own
  /// figures, for a chip the driver has no table for)
  std::string origin;
  bool operator==(const SensorDelay& o) const {
    return chip == o.chip && setting == o.setting && accel_delay_s == o.accel_delay_s &&
           gyro_delay_s == o.gyro_delay_s;
  }
  bool operator!=(const SensorDelay& o) const { return !(*this == o); }
  /// "MPU6050 DLPF_CFG 3: accel 4.9 ms, gyro 4.8 ms (datasheet table)"
  [[nodiscard]] std::string describe() const;
};

/// The outcome of resolving one $INF line: a delay, or a counted reason with a message.
struct InfoResolution {
  std::optional<SensorDelay> delay;
  RejectReason reason = RejectReason::kInfoUnsupported;  ///< valid iff !delay
  std::string message;                                    ///< why it was refused (for the log)
};

/// Gives a well-formed $INF line its meaning. A known chip (MPU6050) takes its delays from the
/// table: a setting the table lacks is kInfoUnknownSetting; delays given on the line must equal
/// the table's within 0.1 ms (its resolution), else kInfoConflict. Another chip must give its
/// delays (kInfoUnknownSetting when it does not), and they are used as given.
InfoResolution resolve_sensor_info(const SensorInfoLine& line);

/// Tolerance of a delay given on the line against the table, s (the table's resolution).
inline constexpr double kInfoDelayToleranceS = 0.1e-3;

/// The $INF line of a simulated sensor that models no low-pass: its samples are the simulator's
/// values at their own stamps, so both delays are 0 (`$INF,1,SIM,,0,0`). Said so that every filter
/// uses 0 instead of assuming half a sample, as it would for a sensor that says nothing.
std::string simulated_sensor_info_line();

}  // namespace poise::imu
