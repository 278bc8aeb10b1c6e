// Vehicle simulator for paper 001's four CarSim cases (Table 1), which we do not have: a point
// vehicle following a road with bank and grade, a sprung body on roll/pitch spring-dampers driven
// by the road-frame specific force, and the signals an ESC cluster + magnetometer give.
//
// Kinematics (world ENU, body FLU, Z-Y-X Euler; see vehicle_estimator.h):
//   road attitude (phi_r, theta_r, psi): the vehicle moves along the road's x axis at speed v:
//     velocity v d, d = [cos(theta_r) cos(psi), cos(theta_r) sin(psi), -sin(theta_r)], a_w = dv/dt d + v dd/dt
//   suspension: I_x phi_v'' = -k_x phi_v - b_x phi_v' + m_s h_s f_r,y ; I_y theta_v'' = -k_y theta_v
//     - b_y theta_v' - m_s h_s f_r,x, with f_r = R(phi_r, theta_r, psi) (a_w + g z) the specific
//     force in road axes (so a bank loads the suspension like a turn does: the body leans downhill)
//   body attitude phi = phi_r + phi_v, theta = theta_r + theta_v (2); yaw psi (no sideslip)
//   sensors: f_b = R(phi, theta, psi) (a_w + g z) -> a_x, a_y; r = -sin(phi) theta' + cos(phi)
//     cos(theta) psi' (body-z rate); B = R H; v. White noise on each, a small yaw-rate bias.
// The simulator's true suspension differs from the estimator's defaults (k +10 %, b -10 %), so the
// EKF's model is not the truth.
// Cases (each: 3 s standstill, accelerate at 2.5 m/s^2, the manoeuvre, brake at 3 m/s^2, 6 s stop):
//   double_lane_change  flat road, 80 km/h, ISO-like double lane change (lateral accel 4 m/s^2)
//   bank_20deg          straight at 80 km/h onto a 20 deg bank (ramp 3 s), braking and stopping on it
//   hill                80 km/h over a hill: 10 % up, crest, 10 % down, flat
//   mountain_road       120 km/h, turns (up to ~3.5 m/s^2) with banked curves (up to ~6 deg), grade
//                       +-6 %, a double lane change; flat again before the stop
#pragma once

#include "poise/vehicle/vehicle_estimator.h"

#include <cstdint>
#include <string>
#include <vector>

namespace poise {

struct VehicleSimConfig {
  std::string scenario = "double_lane_change";
  uint64_t seed = 1;
  double rate_hz = 100.0;
  VehicleModelParams truth_model = [] {
    VehicleModelParams m;
    m.k_x_nm_per_rad *= 1.1;
    m.k_y_nm_per_rad *= 1.1;
    m.b_x_nms_per_rad *= 0.9;
    m.b_y_nms_per_rad *= 0.9;
    return m;
  }();
  Eigen::Vector3d mag_world_ut{0.0, 30.0, -40.0};  ///< H, ENU, uT
  double initial_yaw_rad = 0.5;
  double accel_noise_mps2 = 0.05;      ///< white, per axis
  double yaw_rate_noise_rps = 0.003;   ///< white
  double yaw_rate_bias_max_rps = 0.002;///< constant bias uniform in +- this
  double mag_noise_ut = 0.3;           ///< white, per axis (HMC5883L ~ 0.2 uT)
  double speed_noise_mps = 0.05;       ///< white (clamped at 0)
};

struct VehicleSimSample {
  VehicleSample input;
  double true_roll_rad = 0.0;
  double true_pitch_rad = 0.0;
  double true_yaw_rad = 0.0;
  double road_bank_rad = 0.0;          ///< phi_r
  double road_grade_rad = 0.0;         ///< theta_r (> 0: nose down, i.e. downhill)
  double true_lateral_accel_mps2 = 0.0;///< v psi' (manoeuvre intensity, without gravity)
  double true_speed_mps = 0.0;
  bool true_static = false;            ///< v == 0
};

const std::vector<std::string>& vehicle_sim_scenarios();

/// Generates the whole run; throws std::invalid_argument for an unknown scenario.
std::vector<VehicleSimSample> simulate_vehicle(const VehicleSimConfig& config);

}  // namespace poise
