// A sensor's group delay on a simulated IMU stream: the sample stamped t carries the accelerometer
// and gyroscope of t - d (each its own d), as an MPU6050 behind its digital low-pass filter does
// (the datasheet gives the delay per DLPF_CFG setting: drivers/imu sensor_info.h). Modelled as a
// pure delay, linearly interpolated between the stream's own samples (the filter's amplitude
// response is not modelled: the simulator's motion is far below its bandwidth). Before d of
// history exists, the first sample is held. The magnetometer, pressure and temperature pass
// undelayed (other chips, other filters). Pure: no clocks.
#pragma once

#include "poise/core/types.h"

#include <deque>

namespace poise::sim {

class SampleDelay {
 public:
  /// Delays in seconds, >= 0 (std::invalid_argument otherwise).
  SampleDelay(double accel_delay_s, double gyro_delay_s);
  /// The sample to emit at `s.stamp_ns`: `s` with its accelerometer and gyroscope delayed.
  ImuSample apply(const ImuSample& s);
  /// Forgets the history (the stream restarts).
  void reset() { history_.clear(); }

 private:
  double accel_delay_s_;
  double gyro_delay_s_;
  std::deque<ImuSample> history_;  ///< the input samples of the last max(delay) + one period
};

}  // namespace poise::sim
