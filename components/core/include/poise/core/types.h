// Core sample types shared by drivers, the simulator, estimators and DDS conversions.
//
// Conventions (written once here and in docs/CONVENTIONS.md):
//  - SI units: m/s^2, rad/s, microtesla (uT), Pa, degrees Celsius, m, m/s, s.
//  - Time: int64 nanoseconds (`stamp_ns`) of the sensor's sampling instant on the host clock
//    (CLOCK_MONOTONIC domain unless stated otherwise). Estimators compute dt from stamps only.
//  - World frame ENU (x east, y north, z up); body frame = the IMU's own right-handed axes.
//  - Quaternions: Hamilton, `q_world_body` rotates body vectors into the world frame; stored and
//    exchanged as [w, x, y, z].
//  - Accelerometers measure specific force: at rest they read +g along world up.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>

namespace poise {

/// One IMU sample, already calibrated and in the body frame.
struct ImuSample {
  int64_t stamp_ns = 0;             ///< sampling instant, ns
  uint32_t seq = 0;                 ///< sensor sequence number
  Eigen::Vector3d accel_mps2{0, 0, 0};  ///< specific force, body frame, m/s^2
  Eigen::Vector3d gyro_rps{0, 0, 0};    ///< angular rate, body frame, rad/s
  Eigen::Vector3d mag_ut{0, 0, 0};      ///< magnetic flux density, body frame, uT
  double pressure_pa = 0.0;         ///< static pressure, Pa (valid iff has_pressure)
  double temperature_c = 0.0;       ///< sensor temperature, C (valid iff has_temperature)
  bool has_accel = true;
  bool has_gyro = true;
  /// The sample carries a magnetometer reading (mag_ut valid). false by default: a sample has a
  /// magnetometer only when its source says so (the serial driver per line, the simulator, the DDS
  /// conversion from the wire's valid.mag, BROAD files). Without one (6-axis) every attitude filter
  /// starts at ZYX yaw 0 (quat_tilt_yaw0 in attitude.h) and integrates the gyro about the vertical;
  /// each filter's use_magnetometer (auto | true | false, MagnetometerUse in sample_check.h)
  /// decides what it does with one.
  bool has_mag = false;
  bool has_pressure = false;
  bool has_temperature = false;
};

/// A pose measurement (e.g. from the AprilTag camera), body in world, at its capture time.
struct PoseMeasurement {
  int64_t stamp_ns = 0;                                      ///< capture instant, ns
  Eigen::Vector3d p_world_body_m{0, 0, 0};                   ///< position, world (ENU), m
  Eigen::Quaterniond q_world_body{1, 0, 0, 0};               ///< attitude, Hamilton
  Eigen::Matrix<double, 6, 6> covariance =
      Eigen::Matrix<double, 6, 6>::Identity();  ///< [position m^2 | rotation rad^2 (world-frame
                                                ///< small-angle error)], row-major order p, theta
};

/// A camera pose in the world (e.g. the AprilTag camera's, before any camera-to-body extrinsic),
/// at its capture time.
struct CameraPoseMeasurement {
  int64_t stamp_ns = 0;                                      ///< capture instant, ns
  Eigen::Vector3d p_world_camera_m{0, 0, 0};                 ///< camera origin, world (ENU), m
  Eigen::Quaterniond q_world_camera{1, 0, 0, 0};             ///< camera attitude, Hamilton
  Eigen::Matrix<double, 6, 6> covariance =
      Eigen::Matrix<double, 6, 6>::Identity();  ///< [position m^2 | rotation rad^2 (world-frame
                                                ///< small-angle error)]
};

/// Vehicle speed input (vehicle estimator).
struct VehicleSpeed {
  int64_t stamp_ns = 0;
  double speed_mps = 0.0;  ///< forward speed over ground, m/s (>= 0)
};

}  // namespace poise
