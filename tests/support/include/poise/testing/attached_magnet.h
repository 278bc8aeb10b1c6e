// For the attached-magnet tests of the attitude filters (issue 32, BROAD's "attached magnet"
// trials): the simulator's hand-held run in BROAD's field (44 uT at 70 deg dip: horizontal 15 uT)
// with a magnet fixed to the body attached at rest and removed in the motion. Header-only; the test
// links poise_sim.
#pragma once

#include "poise/sim/sensor_simulator.h"

#include <Eigen/Core>

#include <cstdint>

namespace poise::testing {

inline constexpr double kMagnetRestS = 20.0;      ///< at rest before the motion, s
inline constexpr double kMagnetMotionS = 80.0;    ///< hand-held motion, s
inline constexpr double kMagnetEndRestS = 10.0;   ///< rest after it, s
inline constexpr double kMagnetOnS = 14.0;        ///< the magnet's attachment starts (ramp kMagnetRampS), at rest, s
inline constexpr double kMagnetRampS = 1.5;       ///< s
inline constexpr double kMagnetOffS = 75.0;       ///< its removal starts, in the motion, s

/// 200 Hz, seed 1: rest, hand-held motion (kept near level: the rotation shows the offset's
/// vertical part slowly), rest; `offset_ut` fixed in the body from kMagnetOnS to kMagnetOffS (+
/// ramps); the gyro bias (0.3, -0.2, 0.25) deg/s.
inline sim::SimConfig attached_magnet_hand_held(const Eigen::Vector3d& offset_ut) {
  constexpr double kPi = 3.14159265358979323846;
  sim::SimConfig cfg;
  cfg.rate_hz = 200.0;
  cfg.seed = 1;
  cfg.duration_s = kMagnetRestS + kMagnetMotionS + kMagnetEndRestS;
  cfg.field.magnitude_ut = 44.0;  // BROAD's: horizontal 15 uT
  cfg.field.dip_deg = 70.0;
  cfg.noise.gyro_bias_rps = Eigen::Vector3d(0.3, -0.2, 0.25) * (kPi / 180.0);
  sim::MotionSegment rest;
  rest.duration_s = kMagnetRestS;
  sim::MotionSegment hand;
  hand.name = "hand";
  hand.duration_s = kMagnetMotionS;
  hand.rotation_amplitude_rps = 1.2;
  hand.rotation_freq_hz = 0.3;
  hand.level_gain_per_s = 0.3;
  hand.accel_amplitude_mps2 = 1.5;
  hand.accel_freq_hz = 0.8;
  sim::MotionSegment end = rest;
  end.duration_s = kMagnetEndRestS;
  cfg.segments = {rest, hand, end};
  sim::MagnetEpisode magnet;
  magnet.start_s = kMagnetOnS;
  magnet.ramp_s = kMagnetRampS;
  magnet.hold_s = kMagnetOffS - kMagnetOnS - kMagnetRampS;
  magnet.field_ut = offset_ut;
  magnet.body_fixed = true;
  cfg.magnets = {magnet};
  return cfg;
}

/// The same with the body tumbling (no levelling: the rotation shows the offset along every axis)
/// instead of hand-held.
inline sim::SimConfig attached_magnet_tumbling(const Eigen::Vector3d& offset_ut) {
  sim::SimConfig cfg = attached_magnet_hand_held(offset_ut);
  sim::MotionSegment& motion = cfg.segments[1];
  motion.name = "tumble";
  motion.rotation_amplitude_rps = 2.0;
  motion.rotation_freq_hz = 0.3;
  motion.level_gain_per_s = 0.0;
  motion.accel_amplitude_mps2 = 2.0;
  motion.accel_freq_hz = 0.6;
  return cfg;
}

/// The same run as BROAD's sensor records it (its figures as the filters' defaults assume them):
/// 285.7 Hz, gyro noise 0.15 deg/s, accelerometer 0.05 m/s^2 and magnetometer 0.6 uT per sample;
/// `seed` the noise's.
inline sim::SimConfig attached_magnet_hand_held_broad_noise(const Eigen::Vector3d& offset_ut, uint64_t seed) {
  constexpr double kPi = 3.14159265358979323846;
  sim::SimConfig cfg = attached_magnet_hand_held(offset_ut);
  cfg.rate_hz = 285.7;
  cfg.seed = seed;
  cfg.noise.sigma_gyro_rps = 0.15 * (kPi / 180.0);
  cfg.noise.sigma_accel_mps2 = 0.05;
  cfg.noise.sigma_mag_ut = 0.6;
  return cfg;
}

}  // namespace poise::testing
