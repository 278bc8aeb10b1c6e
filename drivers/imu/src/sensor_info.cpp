#include "poise/imu/sensor_info.h"

#include <cmath>
#include <cstdio>

namespace poise::imu {

const Mpu6050Dlpf* mpu6050_dlpf(int dlpf_cfg) {
  for (const Mpu6050Dlpf& row : kMpu6050Dlpf) {
    if (row.dlpf_cfg == dlpf_cfg) return &row;
  }
  return nullptr;
}

std::string SensorDelay::describe() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "%s%s%s: accel %.2f ms, gyro %.2f ms (%s)", chip.c_str(),
                setting >= 0 ? " setting " : "", setting >= 0 ? std::to_string(setting).c_str() : "",
                accel_delay_s * 1e3, gyro_delay_s * 1e3,
                origin == "table" ? "the driver's datasheet table" : "as the sensor reports it");
  return buf;
}

namespace {

InfoResolution refuse(RejectReason reason, std::string message) {
  InfoResolution r;
  r.reason = reason;
  r.message = std::move(message);
  return r;
}

}  // namespace

InfoResolution resolve_sensor_info(const SensorInfoLine& line) {
  SensorDelay d;
  d.chip = line.chip;
  d.setting = line.setting;
  if (line.chip == "MPU6050") {
    const Mpu6050Dlpf* row = line.setting < 0 ? nullptr : mpu6050_dlpf(line.setting);
    if (row == nullptr) {
      return refuse(RejectReason::kInfoUnknownSetting,
                    "$INF: MPU6050 DLPF_CFG " + std::to_string(line.setting) +
                        " is not in the register map's table (0..6; 7 is reserved): its delay is unknown");
    }
    d.accel_delay_s = row->accel_delay_ms * 1e-3;
    d.gyro_delay_s = row->gyro_delay_ms * 1e-3;
    d.origin = "table";
    if (line.has_delays && (std::fabs(line.accel_delay_us * 1e-6 - d.accel_delay_s) > kInfoDelayToleranceS ||
                            std::fabs(line.gyro_delay_us * 1e-6 - d.gyro_delay_s) > kInfoDelayToleranceS)) {
      return refuse(RejectReason::kInfoConflict,
                    "$INF: MPU6050 DLPF_CFG " + std::to_string(line.setting) + " delays " +
                        std::to_string(line.accel_delay_us) + " / " + std::to_string(line.gyro_delay_us) +
                        " us contradict the datasheet's " + d.describe());
    }
  } else {
    if (!line.has_delays) {
      return refuse(RejectReason::kInfoUnknownSetting,
                    "$INF: chip '" + line.chip +
                        "' has no table in the driver and the line gives no delays: its delay is unknown");
    }
    d.accel_delay_s = line.accel_delay_us * 1e-6;
    d.gyro_delay_s = line.gyro_delay_us * 1e-6;
    d.origin = "sensor";
  }
  InfoResolution r;
  r.delay = d;
  return r;
}

std::string simulated_sensor_info_line() {
  SensorInfoLine info;
  info.version = 1;
  info.chip = "SIM";
  info.has_delays = true;  // both 0 us
  return format_info_line(info);
}

}  // namespace poise::imu
