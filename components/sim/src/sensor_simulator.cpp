#include "poise/sim/sensor_simulator.h"

#include "poise/core/attitude.h"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace poise::sim {
namespace {

constexpr int kSubsteps = 4;
constexpr double kRampS = 0.8;  // envelope ramp at each end of a moving segment, s

// Smootherstep: 0 -> 1 with zero first and second derivatives at both ends; returns s, s', s''
// with respect to x.
struct Smooth {
  double s, ds, dds;
};
Smooth smootherstep(double x) {
  if (x <= 0.0) {
    return {0.0, 0.0, 0.0};
  }
  if (x >= 1.0) {
    return {1.0, 0.0, 0.0};
  }
  const double x2 = x * x;
  const double x3 = x2 * x;
  return {x3 * (x * (6.0 * x - 15.0) + 10.0), 30.0 * x2 * (x - 1.0) * (x - 1.0),
          60.0 * x * (2.0 * x2 - 3.0 * x + 1.0)};
}

// Envelope of a segment of length d (rises over ramp r, falls over ramp r) and its derivatives.
Smooth segment_envelope(double tau, double d) {
  const double r = std::min(kRampS, 0.25 * d);
  if (r <= 0.0) {
    return {0.0, 0.0, 0.0};
  }
  if (tau < r) {
    const Smooth s = smootherstep(tau / r);
    return {s.s, s.ds / r, s.dds / (r * r)};
  }
  if (tau > d - r) {
    const Smooth s = smootherstep((d - tau) / r);
    return {s.s, -s.ds / r, s.dds / (r * r)};
  }
  return {1.0, 0.0, 0.0};
}

double isa_pressure_pa(double altitude_m) {
  constexpr double kP0 = 101325.0;
  constexpr double kT0 = 288.15;
  constexpr double kL = 0.0065;
  constexpr double kR = 287.05;
  constexpr double kG = 9.80665;
  return kP0 * std::pow(1.0 - kL * altitude_m / kT0, kG / (kR * kL));
}

}  // namespace

Eigen::Vector3d MagneticEnvironment::field_world_ut() const {
  const double dip = dip_deg * kRadPerDeg;
  return magnitude_ut * Eigen::Vector3d(0.0, std::cos(dip), -std::sin(dip));
}

double MagnetEpisode::strength(double t_s) const {
  const double tau = t_s - start_s;
  if (tau <= 0.0 || tau >= 2.0 * ramp_s + hold_s) {
    return 0.0;
  }
  if (ramp_s <= 0.0) {
    return 1.0;
  }
  if (tau < ramp_s) {
    const double s = std::sin(0.5 * kPi * tau / ramp_s);
    return s * s;
  }
  if (tau > ramp_s + hold_s) {
    const double s = std::sin(0.5 * kPi * (2.0 * ramp_s + hold_s - tau) / ramp_s);
    return s * s;
  }
  return 1.0;
}

double SimConfig::cycle_s() const {
  double total = 0.0;
  for (const auto& s : segments) {
    total += s.duration_s;
  }
  return total;
}

std::vector<std::string> scenario_names() {
  return {"static_magnet", "fast_motion", "random_motion", "demo", "tour"};
}

namespace {

MotionSegment still(const char* name, double duration_s) {
  MotionSegment m;
  m.name = name;
  m.duration_s = duration_s;
  return m;
}

/// Random rotation (peak rate, typical frequency), a pull towards level, random translation.
MotionSegment moving(const char* name, double duration_s, double rotation_amplitude_rps, double rotation_freq_hz,
                     double level_gain_per_s, double accel_amplitude_mps2, double accel_freq_hz) {
  MotionSegment m = still(name, duration_s);
  m.rotation_amplitude_rps = rotation_amplitude_rps;
  m.rotation_freq_hz = rotation_freq_hz;
  m.level_gain_per_s = level_gain_per_s;
  m.accel_amplitude_mps2 = accel_amplitude_mps2;
  m.accel_freq_hz = accel_freq_hz;
  return m;
}

/// A person's handheld motion (the demo's and the tour's).
MotionSegment handheld(double duration_s) { return moving("handheld", duration_s, 0.8, 0.25, 0.5, 1.5, 0.8); }

/// Handheld motion while climbing at a constant vertical speed (stairs).
MotionSegment stairs(const char* name, double duration_s, double climb_rate_mps) {
  MotionSegment m = handheld(duration_s);
  m.name = name;
  m.climb_rate_mps = climb_rate_mps;
  return m;
}

MagnetEpisode magnet(double start_s, double ramp_s, double hold_s, const Eigen::Vector3d& field_ut,
                     bool body_fixed = false) {
  MagnetEpisode m;
  m.start_s = start_s;
  m.ramp_s = ramp_s;
  m.hold_s = hold_s;
  m.field_ut = field_ut;
  m.body_fixed = body_fixed;
  return m;
}

// The magnet brought near and the one attached to the device (demo and tour).
const Eigen::Vector3d kNearMagnetUt(30.0, 10.0, -20.0);
const Eigen::Vector3d kAttachedMagnetUt(0.0, 25.0, 10.0);

}  // namespace

SimConfig make_scenario(const std::string& name, double rate_hz, uint64_t seed) {
  SimConfig c;
  c.name = name;
  c.rate_hz = rate_hz;
  c.seed = seed;
  c.noise.gyro_bias_rps = Eigen::Vector3d(0.3, -0.2, 0.25) * kRadPerDeg;
  c.q0_world_body = quat_from_euler_zyx(5.0 * kRadPerDeg, -3.0 * kRadPerDeg, 40.0 * kRadPerDeg);
  if (name == "static_magnet") {
    // A static sensor; a magnet approaches (3 s), stays 15 s, leaves; later a second, weaker one
    // (the first ~35 uT, comparable to the earth's field).
    c.segments = {still("static", 80.0)};
    c.duration_s = 80.0;
    c.magnets = {magnet(15.0, 3.0, 15.0, Eigen::Vector3d(25.0, -15.0, 20.0)),
                 magnet(50.0, 3.0, 15.0, Eigen::Vector3d(-10.0, 8.0, -6.0))};
  } else if (name == "fast_motion") {
    const MotionSegment rest = still("static", 5.0);
    // up to ~230 deg/s per axis
    c.segments = {rest, moving("fast", 40.0, 4.0, 1.0, 0.5, 12.0, 1.5), rest};
    c.duration_s = c.cycle_s();
  } else if (name == "random_motion") {
    const MotionSegment slow = moving("random", 30.0, 1.2, 0.3, 0.2, 3.0, 0.6);
    const MotionSegment pause = still("break", 5.0);
    c.segments = {still("static", 5.0), slow, pause, slow, pause};
    c.duration_s = c.cycle_s();
  } else if (name == "demo") {
    // Endless: handheld motion, magnet episodes while resting and while moving, stairs (3 m in 15 s).
    const MotionSegment rest = still("static", 6.0);
    c.segments = {rest, handheld(20.0), rest, stairs("stairs_up", 15.0, 0.2), rest,
                  stairs("stairs_down", 15.0, -0.2), rest, handheld(20.0)};
    c.duration_s = 0.0;
    c.magnets = {magnet(8.0, 2.0, 10.0, kNearMagnetUt), magnet(30.0, 1.0, 6.0, kAttachedMagnetUt, true)};
  } else if (name == "tour") {
    // Every episode of the demo in one 30 s cycle: rest, handheld motion with a magnet brought
    // near and taken away, stairs up and down (1.5 m in 6 s), a magnet attached to the device.
    const MotionSegment pause = still("static", 2.0);
    c.segments = {still("static", 3.0), handheld(8.0), pause, stairs("stairs_up", 6.0, 0.25), pause,
                  stairs("stairs_down", 6.0, -0.25), still("static", 3.0)};  // 3+8+2+6+2+6+3 = 30 s
    c.duration_s = 0.0;
    c.magnets = {magnet(5.0, 1.5, 4.0, kNearMagnetUt), magnet(22.0, 1.0, 4.0, kAttachedMagnetUt, true)};
  } else {
    std::string known;
    for (const auto& n : scenario_names()) {
      known += (known.empty() ? "" : ", ") + n;
    }
    throw std::invalid_argument("unknown simulator scenario '" + name + "' (known: " + known + ")");
  }
  return c;
}

SensorSimulator::SensorSimulator(SimConfig config)
    : cfg_(std::move(config)), rng_(cfg_.seed), q_(cfg_.q0_world_body.normalized()) {
  if (!(cfg_.rate_hz > 0.0) || !std::isfinite(cfg_.rate_hz)) {
    throw std::invalid_argument("simulator rate_hz must be > 0");
  }
  if (cfg_.segments.empty()) {
    throw std::invalid_argument("simulator needs at least one motion segment");
  }
  for (const auto& s : cfg_.segments) {
    if (!(s.duration_s > 0.0)) {
      throw std::invalid_argument("simulator segment '" + s.name + "' needs duration_s > 0");
    }
  }
  bias_ = cfg_.noise.gyro_bias_rps;
  enter_segment(0, 0.0);
}

bool SensorSimulator::done() const {
  return cfg_.duration_s > 0.0 &&
         k_ >= static_cast<uint64_t>(std::llround(cfg_.duration_s * cfg_.rate_hz));
}

void SensorSimulator::enter_segment(size_t index, double start_s) {
  seg_index_ = index;
  seg_start_s_ = start_s;
  const MotionSegment& s = cfg_.segments[index];
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (int axis = 0; axis < 3; ++axis) {
    for (int j = 0; j < 3; ++j) {
      waves_.rot_amp(axis, j) = s.rotation_amplitude_rps / 3.0 * (0.4 + 0.6 * u01(rng_));
      waves_.rot_freq(axis, j) = s.rotation_freq_hz * (0.5 + u01(rng_));
      waves_.rot_phase(axis, j) = 2.0 * kPi * u01(rng_);
      waves_.acc_amp(axis, j) = s.accel_amplitude_mps2 / 3.0 * (0.4 + 0.6 * u01(rng_));
      waves_.acc_freq(axis, j) = s.accel_freq_hz * (0.5 + u01(rng_));
      waves_.acc_phase(axis, j) = 2.0 * kPi * u01(rng_);
    }
  }
  anchor_ = p_;
}

double SensorSimulator::envelope(double t_s) const {
  return segment_envelope(t_s - seg_start_s_, cfg_.segments[seg_index_].duration_s).s;
}

Eigen::Vector3d SensorSimulator::omega_at(double t_s, const Eigen::Quaterniond& q) const {
  const MotionSegment& s = cfg_.segments[seg_index_];
  if (s.rotation_amplitude_rps == 0.0 && s.level_gain_per_s == 0.0) {
    return Eigen::Vector3d::Zero();
  }
  const double env = envelope(t_s);
  Eigen::Vector3d w = Eigen::Vector3d::Zero();
  const double tau = t_s - seg_start_s_;
  for (int axis = 0; axis < 3; ++axis) {
    for (int j = 0; j < 3; ++j) {
      w[axis] += waves_.rot_amp(axis, j) *
                 std::sin(2.0 * kPi * waves_.rot_freq(axis, j) * tau + waves_.rot_phase(axis, j));
    }
  }
  // Pull the body z axis towards world up: omega = k (e_z x up_body) moves up_body to e_z.
  const Eigen::Vector3d up_body = q.conjugate() * Eigen::Vector3d::UnitZ();
  w += s.level_gain_per_s * Eigen::Vector3d::UnitZ().cross(up_body);
  return env * w;
}

Eigen::Vector3d SensorSimulator::accel_at(double t_s, const Eigen::Vector3d& /*p*/,
                                          const Eigen::Vector3d& /*v*/) const {
  // Analytic: p = anchor + env f + climb; a = env'' f + 2 env' f' + env f'' + climb''.
  const MotionSegment& s = cfg_.segments[seg_index_];
  const double tau = t_s - seg_start_s_;
  const Smooth env = segment_envelope(tau, s.duration_s);
  Eigen::Vector3d a = Eigen::Vector3d::Zero();
  if (s.accel_amplitude_mps2 != 0.0) {
    for (int axis = 0; axis < 3; ++axis) {
      double f = 0.0;
      double df = 0.0;
      double ddf = 0.0;
      for (int j = 0; j < 3; ++j) {
        const double om = 2.0 * kPi * waves_.acc_freq(axis, j);
        const double c = waves_.acc_amp(axis, j) / (om * om);
        const double ph = om * tau + waves_.acc_phase(axis, j);
        f += c * std::sin(ph);
        df += c * om * std::cos(ph);
        ddf -= c * om * om * std::sin(ph);
      }
      a[axis] = env.dds * f + 2.0 * env.ds * df + env.s * ddf;
    }
  }
  if (s.climb_rate_mps != 0.0) {
    const Smooth c = smootherstep(tau / s.duration_s);
    a.z() += s.climb_rate_mps * s.duration_s * c.dds / (s.duration_s * s.duration_s);
  }
  return a;
}

void SensorSimulator::advance(double dt_s) {
  // Rotation: midpoint rule on sub-steps. Translation: analytic acceleration, velocity Verlet.
  const double h = dt_s / kSubsteps;
  for (int i = 0; i < kSubsteps; ++i) {
    const double t0 = t_s_ + i * h;
    const Eigen::Vector3d w0 = omega_at(t0, q_);
    const Eigen::Quaterniond q_mid = quat_integrate_body_rate(q_, w0, 0.5 * h);
    const Eigen::Vector3d w_mid = omega_at(t0 + 0.5 * h, q_mid);
    q_ = quat_integrate_body_rate(q_, w_mid, h);
    const Eigen::Vector3d a0 = accel_at(t0, p_, v_);
    const Eigen::Vector3d a1 = accel_at(t0 + h, p_, v_);
    p_ += v_ * h + (h * h / 6.0) * (2.0 * a0 + a1);
    v_ += 0.5 * h * (a0 + a1);
  }
}

SimSample SensorSimulator::next() {
  const double dt = 1.0 / cfg_.rate_hz;
  if (k_ > 0) {
    // Segment change happens on a sample boundary after the previous segment has ended.
    advance(dt);
    t_s_ = static_cast<double>(k_) * dt;
    const MotionSegment& s = cfg_.segments[seg_index_];
    if (t_s_ >= seg_start_s_ + s.duration_s - 1e-9) {
      v_.setZero();  // exact rest at boundaries (the envelope already brought it to ~0)
      enter_segment((seg_index_ + 1) % cfg_.segments.size(), seg_start_s_ + s.duration_s);
    }
    if (cfg_.noise.gyro_bias_walk_rps_per_sqrt_s > 0.0) {
      const double sd = cfg_.noise.gyro_bias_walk_rps_per_sqrt_s * std::sqrt(dt);
      bias_ += sd * Eigen::Vector3d(normal_(rng_), normal_(rng_), normal_(rng_));
    }
  }
  SimSample out;
  Truth& tr = out.truth;
  tr.t_s = t_s_;
  tr.stamp_ns = cfg_.start_stamp_ns + static_cast<int64_t>(std::llround(t_s_ * 1e9));
  tr.q_world_body = quat_canonical(q_);
  tr.omega_body_rps = omega_at(t_s_, q_);
  tr.p_world_m = p_;
  tr.v_world_mps = v_;
  tr.a_world_mps2 = accel_at(t_s_, p_, v_);
  const Eigen::Matrix3d r_wb = q_.toRotationMatrix();
  tr.ext_accel_body_mps2 = r_wb.transpose() * tr.a_world_mps2;
  tr.gyro_bias_rps = bias_;
  tr.mag_earth_world_ut = cfg_.field.field_world_ut();
  const double cycle = cfg_.cycle_s();
  const double t_cycle = cfg_.duration_s <= 0.0 && cycle > 0.0 ? std::fmod(t_s_, cycle) : t_s_;
  Eigen::Vector3d d_world = Eigen::Vector3d::Zero();
  Eigen::Vector3d d_body = Eigen::Vector3d::Zero();
  for (const auto& m : cfg_.magnets) {
    const double k = m.strength(t_cycle);
    if (k > 0.0) {
      (m.body_fixed ? d_body : d_world) += k * m.field_ut;
    }
  }
  tr.mag_disturbance_world_ut = d_world + r_wb * d_body;
  tr.mag_disturbance_body_ut = r_wb.transpose() * d_world + d_body;
  tr.altitude_m = cfg_.start_altitude_m + p_.z();
  const MotionSegment& seg = cfg_.segments[seg_index_];
  tr.moving = seg.rotation_amplitude_rps != 0.0 || seg.accel_amplitude_mps2 != 0.0 ||
              seg.climb_rate_mps != 0.0;
  tr.segment = seg.name;

  ImuSample& imu = out.imu;
  const SensorNoise& n = cfg_.noise;
  auto noise3 = [&](double sd) {
    return Eigen::Vector3d(sd * normal_(rng_), sd * normal_(rng_), sd * normal_(rng_));
  };
  imu.stamp_ns = tr.stamp_ns;
  imu.seq = static_cast<uint32_t>(k_);
  imu.gyro_rps = tr.omega_body_rps + bias_ + noise3(n.sigma_gyro_rps);
  imu.accel_mps2 = r_wb.transpose() * (tr.a_world_mps2 + cfg_.gravity_mps2 * Eigen::Vector3d::UnitZ()) +
                   noise3(n.sigma_accel_mps2);
  imu.mag_ut = r_wb.transpose() * (tr.mag_earth_world_ut + tr.mag_disturbance_world_ut) +
               noise3(n.sigma_mag_ut);
  imu.has_mag = true;  // the simulated sensor is 9-axis
  imu.has_pressure = cfg_.has_pressure;
  if (cfg_.has_pressure) {
    imu.pressure_pa = isa_pressure_pa(tr.altitude_m) + n.baro_drift_pa_per_s * t_s_ +
                      n.sigma_pressure_pa * normal_(rng_);
  }
  imu.has_temperature = true;
  imu.temperature_c = 25.0;
  ++k_;
  return out;
}

std::vector<SimSample> SensorSimulator::run() {
  if (cfg_.duration_s <= 0.0) {
    throw std::invalid_argument("SensorSimulator::run() needs a finite duration_s");
  }
  std::vector<SimSample> out;
  out.reserve(static_cast<size_t>(cfg_.duration_s * cfg_.rate_hz) + 2);
  while (!done()) {
    out.push_back(next());
  }
  return out;
}

}  // namespace poise::sim
