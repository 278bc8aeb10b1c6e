// For the attitude filters' tests of a field whose horizontal direction turns where the sensor
// goes (issue 31 / 32, BROAD trial 30: a magnet fixed in the room): the simulator with the Earth
// field turned about the vertical by delta(t) = amplitude sin(2 pi (t - start) / period) from
// `start`, its norm and dip unchanged (a field gate accepts it). Header-only; the test links poise_sim.
#pragma once

#include "poise/sim/sensor_simulator.h"

#include <Eigen/Geometry>

#include <cmath>

namespace poise::testing {

struct FieldRotation {
  double amplitude_rad = 0.0;  ///< the horizontal rotation's amplitude, rad
  double period_s = 20.0;      ///< its period, s
  double start_s = 20.0;       ///< it begins, s
  /// delta at time t (s of the simulator's truth), rad
  [[nodiscard]] double at(double t_s) const {
    constexpr double kPi = 3.14159265358979323846;
    const double t = t_s - start_s;
    return t > 0.0 ? amplitude_rad * std::sin(2.0 * kPi * t / period_s) : 0.0;
  }
};

/// The simulator with the Earth field's horizontal direction turned by rotation.at(t) about the
/// vertical: mag += R^T (Rz(delta) - I) m_world (the magnetometer is linear in the field).
class RotatedFieldSim {
 public:
  RotatedFieldSim(const sim::SimConfig& cfg, const FieldRotation& rotation) : sim_(cfg), rotation_(rotation) {}
  [[nodiscard]] bool done() const { return sim_.done(); }
  sim::SimSample next() {
    sim::SimSample s = sim_.next();
    const double delta = rotation_.at(s.truth.t_s);
    if (delta != 0.0) {
      const Eigen::Vector3d m = s.truth.mag_earth_world_ut;
      const Eigen::Vector3d turned = Eigen::AngleAxisd(delta, Eigen::Vector3d::UnitZ()) * m;
      s.imu.mag_ut += s.truth.q_world_body.conjugate() * (turned - m);
    }
    return s;
  }

 private:
  sim::SensorSimulator sim_;
  FieldRotation rotation_;
};

}  // namespace poise::testing
