// Sensor calibration applied by the driver before publishing (pure).
//
// In the sensor's own axes (s), then remapped to the body frame (b):
//   gyro_s  = diag(gyro_scale)  (gyro_raw  - gyro_bias_rps)
//   accel_s = diag(accel_scale) (accel_raw - accel_bias_mps2)
//   mag_s   = mag_soft_iron (mag_raw - mag_hard_iron_ut)          (soft iron: 3x3, hard iron: uT)
//   x_b     = R_axes x_s   (R_axes a signed permutation with det +1, per chip: imu = MPU6050
//                          accel+gyro, mag = HMC5883L)
#pragma once

#include <array>
#include <string>

#include <Eigen/Core>

#include "poise/core/types.h"
#include "poise/imu/protocol.h"

namespace poise::imu {

/// A signed axis permutation: body axis i = sign[i] * sensor axis index[i].
struct AxisMap {
  std::array<int, 3> index{0, 1, 2};
  std::array<int, 3> sign{1, 1, 1};
  /// Parses "+x,+y,+z" style text ("x,-z,y", "-y,x,z", ...). Returns false with a message if the
  /// text is malformed, repeats an axis or describes a left-handed (det -1) frame.
  static bool parse(const std::string& text, AxisMap* out, std::string* error);
  [[nodiscard]] std::string to_string() const;
  [[nodiscard]] Eigen::Matrix3d matrix() const;  ///< x_body = matrix() * x_sensor
};

struct Calibration {
  AxisMap imu_axes;  ///< MPU6050 (accel + gyro) sensor axes -> body
  AxisMap mag_axes;  ///< HMC5883L axes -> body
  Eigen::Vector3d gyro_bias_rps{0, 0, 0};
  Eigen::Vector3d gyro_scale{1, 1, 1};
  Eigen::Vector3d accel_bias_mps2{0, 0, 0};
  Eigen::Vector3d accel_scale{1, 1, 1};
  Eigen::Vector3d mag_hard_iron_ut{0, 0, 0};
  Eigen::Matrix3d mag_soft_iron = Eigen::Matrix3d::Identity();

  /// Empty when valid, else what is wrong (finite values, scales in [0.5, 2], soft iron
  /// well-conditioned).
  [[nodiscard]] std::string validate() const;
  /// Calibrated sample in the body frame; stamp/seq are left for the caller.
  void apply(const RawSample& raw, ImuSample* out) const;
  /// The inverse of apply(): the raw sensor-axes sample a calibrated one came from (used to
  /// re-calibrate from a published topic). Requires validate() to pass.
  [[nodiscard]] RawSample invert(const ImuSample& calibrated) const;
};

}  // namespace poise::imu
