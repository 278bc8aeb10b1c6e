// The parallel KF told the simulated sensor (shared by the tests that run it on poise_sim's scenarios).
#pragma once

#include "poise/parallel_kf/parallel_kf.h"
#include "poise/sim/sensor_simulator.h"

namespace poise {

/// The filter told what the simulated sensor is (its keys describe the sensor): the heading's
/// gyro and magnetometer noise per sample, the simulator's gravity and Earth field (known, as
/// GaussNewtonChiSquare's), no gyro scale error, no delay (its bias walk: run_at_rest in parallel_kf_chi_square_test.cpp).
inline ParallelKfParams told_the_simulated_sensor(const sim::SimConfig& cfg) {
  ParallelKfParams p = ParallelKfParams::defaults();
  p.tilt.gravity_mps2 = cfg.gravity_mps2;
  p.sigma_gyro_heading_rps = cfg.noise.sigma_gyro_rps;
  p.sigma_mag_ut = cfg.noise.sigma_mag_ut;
  p.motion_gyro_scale_error = 0.0;
  p.field_magnitude_ut = cfg.field.magnitude_ut;
  p.dip_deg = cfg.field.dip_deg;
  p.imu_delay_s = 0.0;  // the simulator's samples are at their stamps
  return p;
}

}  // namespace poise
