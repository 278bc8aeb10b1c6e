// SensorSimulator: a seeded trajectory -> consistent IMU stream (gyro, accelerometer,
// magnetometer, barometer) with noise, gyro bias, external acceleration and injected magnetic
// disturbances, plus the truth that produced it. For scenario tests, the serial-IMU simulator
// and the demo. Pure C++/Eigen: no clocks (time advances by 1/rate per next()).
//
// Frames and models (conventions of poise/core/types.h)
//   world ENU, body = IMU axes; q_world_body (truth) rotates body vectors into the world.
//   gyro  = omega_body + bias + n_g                       (bias: initial value + random walk)
//   accel = R^T (a_world + g e_z) + n_a                   (specific force; R = R_world_body)
//   mag   = R^T (m_world + d_world) + d_body + n_m        (m_world from magnitude + dip, ENU,
//                                                          magnetic north = +y)
//   p_pa  = P0 (1 - L h / T0)^(g / (R_air L)) + drift + n_p   (ISA, h = altitude + z)
// Motion: per segment a smooth random angular velocity (sum of sinusoids, enveloped so segment
// boundaries are continuous) with an optional pull back towards level, and a world acceleration
// (sum of sinusoids, damped towards an anchor) plus an optional constant vertical climb rate
// (stairs). Truth is what the simulator integrates (4 sub-steps per sample), so the signals are
// consistent with it to integration accuracy.
#pragma once

#include "poise/core/types.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace poise::sim {

/// Sensor imperfections. Defaults: roughly a GY-87 (MPU6050 + HMC5883L + BMP180).
struct SensorNoise {
  double sigma_gyro_rps = 0.05 * 3.14159265358979323846 / 180.0;  ///< white gyro noise std, rad/s
  double sigma_accel_mps2 = 0.04;                                  ///< white accel noise std, m/s^2
  double sigma_mag_ut = 0.2;                                       ///< white mag noise std, uT
  double sigma_pressure_pa = 3.0;                                  ///< white baro noise std, Pa
  Eigen::Vector3d gyro_bias_rps{0.0, 0.0, 0.0};                    ///< initial gyro bias, rad/s
  double gyro_bias_walk_rps_per_sqrt_s = 0.0;                      ///< bias random walk, rad/s/sqrt(s)
  double baro_drift_pa_per_s = 0.0;                                ///< linear baro drift, Pa/s
};

/// The undisturbed local magnetic field (ENU, magnetic north along +y).
struct MagneticEnvironment {
  double magnitude_ut = 50.0;  ///< |m|, uT
  double dip_deg = 60.0;       ///< inclination below the horizon (northern hemisphere > 0), deg
  [[nodiscard]] Eigen::Vector3d field_world_ut() const;
};

/// A magnetic disturbance episode: the field ramps up smoothly over ramp_s (a magnet approaching),
/// holds for hold_s, then ramps down (leaving). World-fixed (a magnet near the sensor, a steel
/// plate) or body-fixed (a magnet attached to the device).
struct MagnetEpisode {
  double start_s = 0.0;
  double ramp_s = 2.0;
  double hold_s = 10.0;
  Eigen::Vector3d field_ut{20.0, 0.0, 0.0};  ///< full-strength disturbance (world or body frame), uT
  bool body_fixed = false;
  /// Strength in [0, 1] at time t (smooth sin^2 ramps).
  [[nodiscard]] double strength(double t_s) const;
};

/// One motion segment.
struct MotionSegment {
  std::string name = "static";
  double duration_s = 10.0;
  double rotation_amplitude_rps = 0.0;  ///< peak angular rate per axis (0 = no rotation)
  double rotation_freq_hz = 0.3;        ///< typical frequency of the random rotation
  double level_gain_per_s = 0.0;        ///< pull towards level (keeps a handheld device upright)
  double accel_amplitude_mps2 = 0.0;    ///< peak world acceleration per axis (0 = no translation)
  double accel_freq_hz = 0.5;           ///< typical frequency of the translation
  double climb_rate_mps = 0.0;          ///< constant vertical speed (stairs, lift), m/s
};

/// Everything that defines a simulated run. `make_scenario(name)` returns a filled one.
struct SimConfig {
  std::string name = "custom";
  double rate_hz = 100.0;                 ///< output sample rate, Hz
  uint64_t seed = 1;                      ///< RNG seed (noise and random motion)
  double duration_s = 60.0;               ///< <= 0: endless (segments and magnets repeat)
  int64_t start_stamp_ns = 1'000'000'000;  ///< stamp of the first sample
  SensorNoise noise;
  MagneticEnvironment field;
  std::vector<MotionSegment> segments;    ///< played in order, repeated when exhausted
  std::vector<MagnetEpisode> magnets;     ///< times relative to the start of each repetition
  Eigen::Quaterniond q0_world_body = Eigen::Quaterniond::Identity();
  double start_altitude_m = 100.0;        ///< altitude of the start point (for the barometer), m
  double gravity_mps2 = 9.80665;
  bool has_pressure = true;
  [[nodiscard]] double cycle_s() const;   ///< total duration of `segments`
};

/// Names accepted by make_scenario(): static_magnet, fast_motion, random_motion, demo.
std::vector<std::string> scenario_names();
/// A named scenario at `rate_hz` with `seed`. Throws std::invalid_argument for unknown names.
SimConfig make_scenario(const std::string& name, double rate_hz = 100.0, uint64_t seed = 1);

/// The truth behind one sample.
struct Truth {
  int64_t stamp_ns = 0;
  double t_s = 0.0;                          ///< time since the first sample, s
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();
  Eigen::Vector3d omega_body_rps{0, 0, 0};   ///< true angular rate, body, rad/s
  Eigen::Vector3d p_world_m{0, 0, 0};        ///< position, ENU, m (z = height above start)
  Eigen::Vector3d v_world_mps{0, 0, 0};      ///< velocity, ENU, m/s
  Eigen::Vector3d a_world_mps2{0, 0, 0};     ///< kinematic acceleration, ENU, m/s^2
  Eigen::Vector3d ext_accel_body_mps2{0, 0, 0};  ///< R^T a_world: external accel seen in body
  Eigen::Vector3d gyro_bias_rps{0, 0, 0};
  Eigen::Vector3d mag_earth_world_ut{0, 0, 0};   ///< undisturbed field, world
  Eigen::Vector3d mag_disturbance_world_ut{0, 0, 0};  ///< total disturbance, world frame, uT
  Eigen::Vector3d mag_disturbance_body_ut{0, 0, 0};   ///< the same, body frame, uT
  double altitude_m = 0.0;                   ///< start_altitude_m + p_world.z
  bool moving = false;                       ///< inside a segment with rotation or translation
  std::string segment;                       ///< current segment name
};

struct SimSample {
  ImuSample imu;
  Truth truth;
};

class SensorSimulator {
 public:
  /// Throws std::invalid_argument for an unusable config (rate <= 0, no segments...).
  explicit SensorSimulator(SimConfig config);

  /// True once duration_s has elapsed (never for duration_s <= 0).
  [[nodiscard]] bool done() const;
  /// The next sample (and the truth at its instant).
  SimSample next();
  /// All remaining samples (only for finite durations).
  std::vector<SimSample> run();

  [[nodiscard]] const SimConfig& config() const { return cfg_; }
  [[nodiscard]] uint64_t samples_emitted() const { return k_; }

 private:
  struct SegmentWaves {
    Eigen::Matrix<double, 3, 3> rot_amp, rot_freq, rot_phase;
    Eigen::Matrix<double, 3, 3> acc_amp, acc_freq, acc_phase;
  };
  void enter_segment(size_t index, double start_s);
  void advance(double dt_s);
  [[nodiscard]] double envelope(double t_s) const;
  [[nodiscard]] Eigen::Vector3d omega_at(double t_s, const Eigen::Quaterniond& q) const;
  [[nodiscard]] Eigen::Vector3d accel_at(double t_s, const Eigen::Vector3d& p,
                                         const Eigen::Vector3d& v) const;

  SimConfig cfg_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  uint64_t k_ = 0;
  double t_s_ = 0.0;
  size_t seg_index_ = 0;
  double seg_start_s_ = 0.0;
  SegmentWaves waves_{};
  Eigen::Quaterniond q_;
  Eigen::Vector3d p_{0, 0, 0};
  Eigen::Vector3d v_{0, 0, 0};
  Eigen::Vector3d anchor_{0, 0, 0};
  Eigen::Vector3d bias_{0, 0, 0};
};

}  // namespace poise::sim
