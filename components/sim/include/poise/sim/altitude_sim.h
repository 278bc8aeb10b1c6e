// Altitude simulator: a hand-held GY-87 (MPU6050 IMU + BMP180 barometer) moved as in the five
// tests of paper 003 (section VI.1), with exact ground truth. Seeded and bit-reproducible on one
// platform. Pure C++ (no clocks, no I/O).
//
// Profiles (paper 003 Test 1-5; durations and amplitudes are ours, the paper gives none):
//   random            Test 1: 5 s still, 50 s random attitude + position changes (0.1-0.45 Hz,
//                     vertical std ~0.35 m), 5 s still
//   random_fast       Test 2: as Test 1 but faster (0.3-1.0 Hz, vertical speed up to ~2 m/s)
//   stairs_1_5m       Test 3: 1.5 m up in 3 steps of 0.5 m with 2.5 s stops, then down the same way
//   stairs_3m         Test 4: 3 m up in 6 steps of 0.5 m with stops, then down
//   climb_descend_3m  Test 5: 3 m continuous climb (~12 s), stop at the top, continuous descent
// Motion other than the vertical one (hand wobble: attitude +-5..30 deg, horizontal sway) keeps
// the device from looking stationary while it moves, as a hand would.
// Sensor model (noise figures from the data sheets of paper 003 Table 1; biases after calibration):
//   accel: white 0.03 m/s^2 per axis + constant bias U(-b, b) per axis (b = 0.05 m/s^2)
//   gyro: white 0.05 deg/s + constant bias U(-0.2, 0.2) deg/s
//   baro: white 3 Pa (0.03 hPa RMS), random-walk drift 0.3 Pa/sqrt(s), 1 Pa (0.01 hPa) resolution
// Truth: height above the reference pressure level (ground at `ground_height_m`), vertical velocity.
#pragma once

#include "poise/core/types.h"

#include <cstdint>
#include <string>
#include <vector>

namespace poise {

struct AltitudeSimConfig {
  std::string profile = "random";
  uint64_t seed = 1;
  double rate_hz = 100.0;                 ///< IMU and barometer rate, Hz
  double accel_noise_mps2 = 0.03;         ///< white noise std per axis, m/s^2
  double accel_bias_max_mps2 = 0.05;      ///< bias uniform in +- this per axis, m/s^2
  double gyro_noise_rps = 0.05 * 3.14159265358979323846 / 180.0;   ///< rad/s
  double gyro_bias_max_rps = 0.2 * 3.14159265358979323846 / 180.0; ///< rad/s
  double baro_noise_pa = 3.0;             ///< white noise std, Pa (BMP180: 0.03 hPa RMS)
  double baro_drift_pa_per_sqrt_s = 0.3;  ///< random-walk drift density, Pa/sqrt(s)
  double baro_resolution_pa = 1.0;        ///< quantisation step, Pa
  double reference_pressure_pa = 101325.0;///< pressure at height 0 (what the filter's QNH should be)
  double ground_height_m = 30.0;          ///< start height above the reference level, m
};

/// One simulated instant: the sensor sample and the truth.
struct AltitudeSimSample {
  ImuSample imu;
  double true_height_m = 0.0;
  double true_vertical_velocity_mps = 0.0;
  double true_vertical_accel_mps2 = 0.0;
  bool true_stationary = false;
};

/// The profile names in paper order.
const std::vector<std::string>& altitude_sim_profiles();

/// Generates the whole run; throws std::invalid_argument for an unknown profile.
std::vector<AltitudeSimSample> simulate_altitude(const AltitudeSimConfig& config);

}  // namespace poise
