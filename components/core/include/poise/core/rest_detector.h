// Rest detection shared by the attitude filters: the gyro and the accelerometer stay close to
// their own low-passes (and the low-passed gyro, less a known offset such as the bias estimate,
// stays small) for a minimum time. Thresholds in SI units, times in seconds. A value type: its
// state can be copied with the filter's state (replay).
#pragma once

#include <Eigen/Core>

namespace poise {

struct RestParams {
  double gyro_max_rps = 0.0349;  ///< 2 deg/s
  double accel_max_mps2 = 0.5;
  double min_s = 1.5;            ///< still for at least this long, s
  double filter_tau_s = 0.5;     ///< first-order low-pass time constant, s
};

struct RestDetector {
  Eigen::Vector3d gyro_lp{0, 0, 0};   ///< rad/s
  Eigen::Vector3d accel_lp{0, 0, 0};  ///< m/s^2
  double still_s = 0.0;               ///< how long the sensor has been still, s
  bool rest = false;
  bool started = false;

  /// Starts the low-passes on this sample (not at rest).
  void start(const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& accel_mps2) {
    gyro_lp = gyro_rps;
    accel_lp = accel_mps2;
    still_s = 0.0;
    rest = false;
    started = true;
  }

  /// One sample dt_s after the previous one; `gyro_offset_rps` is subtracted from the low-passed
  /// gyro before its magnitude test (e.g. the current bias estimate). Returns `rest`.
  bool step(const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& accel_mps2, double dt_s, const RestParams& p,
            const Eigen::Vector3d& gyro_offset_rps = Eigen::Vector3d::Zero()) {
    if (!started) {
      start(gyro_rps, accel_mps2);
    }
    const double a = dt_s / (p.filter_tau_s + dt_s);
    gyro_lp += a * (gyro_rps - gyro_lp);
    accel_lp += a * (accel_mps2 - accel_lp);
    const bool still = (gyro_lp - gyro_offset_rps).norm() < p.gyro_max_rps &&
                       (gyro_rps - gyro_lp).norm() < p.gyro_max_rps &&
                       (accel_mps2 - accel_lp).norm() < p.accel_max_mps2;
    still_s = still ? still_s + dt_s : 0.0;
    rest = still_s >= p.min_s;
    return rest;
  }
};

}  // namespace poise
