#include "poise/sim/altitude_sim.h"

#include "poise/altitude/altitude_filter.h"
#include "poise/core/attitude.h"

#include <cmath>
#include <random>
#include <stdexcept>

namespace poise {
namespace {

/// A scalar signal with its first two time derivatives.
struct Sig {
  double v = 0.0;
  double d1 = 0.0;
  double d2 = 0.0;
};

Sig operator*(const Sig& a, const Sig& b) {
  return {a.v * b.v, a.d1 * b.v + a.v * b.d1, a.d2 * b.v + 2.0 * a.d1 * b.d1 + a.v * b.d2};
}
Sig operator+(const Sig& a, const Sig& b) { return {a.v + b.v, a.d1 + b.d1, a.d2 + b.d2}; }

/// Quintic smoothstep from 0 to 1 over [t0, t0 + T] (minimum-jerk profile).
Sig smoothstep(double t, double t0, double duration) {
  if (t <= t0) {
    return {0.0, 0.0, 0.0};
  }
  if (t >= t0 + duration) {
    return {1.0, 0.0, 0.0};
  }
  const double s = (t - t0) / duration;
  const double s2 = s * s;
  const double s3 = s2 * s;
  return {10.0 * s3 - 15.0 * s3 * s + 6.0 * s3 * s2,
          (30.0 * s2 - 60.0 * s3 + 30.0 * s2 * s2) / duration,
          (60.0 * s - 180.0 * s2 + 120.0 * s3) / (duration * duration)};
}

/// 1 on [t0 + ramp, t1 - ramp], smooth ramps to 0 outside [t0, t1].
Sig window(double t, double t0, double t1, double ramp) {
  const Sig up = smoothstep(t, t0, ramp);
  const Sig down = smoothstep(t, t1 - ramp, ramp);
  return {up.v - down.v, up.d1 - down.d1, up.d2 - down.d2};
}

struct Sine {
  double amp = 0.0;
  double omega = 0.0;
  double phase = 0.0;
};

Sig sines(const std::vector<Sine>& comps, double t) {
  Sig out;
  for (const auto& c : comps) {
    const double a = c.omega * t + c.phase;
    out.v += c.amp * std::sin(a);
    out.d1 += c.amp * c.omega * std::cos(a);
    out.d2 -= c.amp * c.omega * c.omega * std::sin(a);
  }
  return out;
}

/// One motion segment of a stepped vertical profile: from z0 by dz over [t0, t0 + T].
struct Step {
  double t0;
  double duration;
  double dz;
};

/// The trajectory description of one profile.
struct Trajectory {
  double duration_s = 60.0;
  // Vertical: sum of sines * window, plus min-jerk steps.
  std::vector<Sine> z_sines;
  std::vector<Step> z_steps;
  // Horizontal sway and attitude (roll, pitch, yaw) sines.
  std::vector<Sine> x_sines;
  std::vector<Sine> y_sines;
  std::vector<Sine> roll_sines;
  std::vector<Sine> pitch_sines;
  std::vector<Sine> yaw_sines;
  double yaw0 = 0.3;
  // Envelope: a window [t0, t1] (random profiles) or the step segments (bump per segment).
  bool use_window = true;
  double win_t0 = 5.0;
  double win_t1 = 55.0;
  double win_ramp = 1.0;

  [[nodiscard]] Sig envelope(double t) const {
    if (use_window) {
      return window(t, win_t0, win_t1, win_ramp);
    }
    for (const auto& s : z_steps) {
      if (t > s.t0 && t < s.t0 + s.duration) {
        const double half = 0.5 * s.duration;
        return window(t, s.t0, s.t0 + s.duration, half);  // a smooth bump
      }
    }
    return {};
  }
};

std::vector<Sine> random_sines(std::mt19937_64& rng, int n, double f_lo, double f_hi, double a_lo,
                               double a_hi) {
  std::uniform_real_distribution<double> uf(f_lo, f_hi);
  std::uniform_real_distribution<double> ua(a_lo, a_hi);
  std::uniform_real_distribution<double> up(0.0, 2.0 * kPi);
  std::vector<Sine> out;
  for (int i = 0; i < n; ++i) {
    Sine s;
    s.amp = ua(rng);
    s.omega = 2.0 * kPi * uf(rng);
    s.phase = up(rng);
    out.push_back(s);
  }
  return out;
}

Trajectory make_trajectory(const std::string& profile, std::mt19937_64& rng) {
  Trajectory tr;
  constexpr double kDeg = kRadPerDeg;
  if (profile == "random" || profile == "random_fast") {
    const bool fast = profile == "random_fast";
    tr.duration_s = 60.0;
    const double f_lo = fast ? 0.3 : 0.1;
    const double f_hi = fast ? 1.0 : 0.45;
    tr.z_sines = random_sines(rng, 4, f_lo, f_hi, fast ? 0.12 : 0.15, fast ? 0.3 : 0.35);
    tr.x_sines = random_sines(rng, 3, f_lo, f_hi, 0.1, 0.4);
    tr.y_sines = random_sines(rng, 3, f_lo, f_hi, 0.1, 0.4);
    tr.roll_sines = random_sines(rng, 3, f_lo, 1.2 * f_hi, 5.0 * kDeg, 15.0 * kDeg);
    tr.pitch_sines = random_sines(rng, 3, f_lo, 1.2 * f_hi, 5.0 * kDeg, 15.0 * kDeg);
    tr.yaw_sines = random_sines(rng, 2, f_lo, f_hi, 10.0 * kDeg, 30.0 * kDeg);
    return tr;
  }
  // Stepped profiles: hand wobble during each motion segment (walking, ~1-2 Hz).
  tr.use_window = false;
  tr.x_sines = random_sines(rng, 2, 0.8, 1.6, 0.02, 0.06);
  tr.y_sines = random_sines(rng, 2, 0.8, 1.6, 0.02, 0.06);
  tr.roll_sines = random_sines(rng, 2, 0.8, 2.0, 2.0 * kDeg, 6.0 * kDeg);
  tr.pitch_sines = random_sines(rng, 2, 0.8, 2.0, 2.0 * kDeg, 6.0 * kDeg);
  tr.yaw_sines = random_sines(rng, 2, 0.5, 1.0, 3.0 * kDeg, 8.0 * kDeg);
  if (profile == "stairs_1_5m" || profile == "stairs_3m") {
    const int steps = profile == "stairs_3m" ? 6 : 3;
    constexpr double kStepM = 0.5;
    constexpr double kMoveS = 1.5;
    constexpr double kStopS = 2.5;
    double t = 5.0;
    for (int dir : {1, -1}) {
      for (int i = 0; i < steps; ++i) {
        tr.z_steps.push_back({t, kMoveS, dir * kStepM});
        t += kMoveS + kStopS;
      }
    }
    tr.duration_s = t + 2.5;
    return tr;
  }
  if (profile == "climb_descend_3m") {
    tr.z_steps.push_back({5.0, 12.0, 3.0});
    tr.z_steps.push_back({22.0, 12.0, -3.0});
    tr.duration_s = 39.0;
    return tr;
  }
  throw std::invalid_argument("unknown altitude profile '" + profile +
                              "' (random, random_fast, stairs_1_5m, stairs_3m, climb_descend_3m)");
}

}  // namespace

const std::vector<std::string>& altitude_sim_profiles() {
  static const std::vector<std::string> kProfiles = {"random", "random_fast", "stairs_1_5m",
                                                     "stairs_3m", "climb_descend_3m"};
  return kProfiles;
}

std::vector<AltitudeSimSample> simulate_altitude(const AltitudeSimConfig& cfg) {
  if (!(cfg.rate_hz > 0.0) || !std::isfinite(cfg.rate_hz)) {
    throw std::invalid_argument("altitude simulator: rate_hz must be > 0");
  }
  std::mt19937_64 traj_rng(cfg.seed * 0x9E3779B97F4A7C15ULL + 1U);
  std::mt19937_64 rng(cfg.seed);
  const Trajectory tr = make_trajectory(cfg.profile, traj_rng);

  std::uniform_real_distribution<double> u11(-1.0, 1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  const Eigen::Vector3d accel_bias(cfg.accel_bias_max_mps2 * u11(rng),
                                   cfg.accel_bias_max_mps2 * u11(rng),
                                   cfg.accel_bias_max_mps2 * u11(rng));
  const Eigen::Vector3d gyro_bias(cfg.gyro_bias_max_rps * u11(rng), cfg.gyro_bias_max_rps * u11(rng),
                                  cfg.gyro_bias_max_rps * u11(rng));

  const double dt = 1.0 / cfg.rate_hz;
  const auto n = static_cast<std::size_t>(std::floor(tr.duration_s * cfg.rate_hz)) + 1U;
  std::vector<AltitudeSimSample> out;
  out.reserve(n);
  double drift_pa = 0.0;
  const int64_t t0_ns = 1'000'000'000;  // arbitrary sensor clock origin
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * dt;
    const Sig env = tr.envelope(t);
    Sig z = sines(tr.z_sines, t) * env;
    for (const auto& s : tr.z_steps) {
      const Sig st = smoothstep(t, s.t0, s.duration);
      z = z + Sig{s.dz * st.v, s.dz * st.d1, s.dz * st.d2};
    }
    const Sig x = sines(tr.x_sines, t) * env;
    const Sig y = sines(tr.y_sines, t) * env;
    const Sig roll = sines(tr.roll_sines, t) * env;
    const Sig pitch = sines(tr.pitch_sines, t) * env;
    Sig yaw = sines(tr.yaw_sines, t) * env;
    yaw.v += tr.yaw0;

    const Eigen::Quaterniond q_wb = quat_from_euler_zyx(roll.v, pitch.v, yaw.v);
    const double sr = std::sin(roll.v);
    const double cr = std::cos(roll.v);
    const double sp = std::sin(pitch.v);
    const double cp = std::cos(pitch.v);
    const Eigen::Vector3d omega_b(roll.d1 - sp * yaw.d1, cr * pitch.d1 + sr * cp * yaw.d1,
                                  -sr * pitch.d1 + cr * cp * yaw.d1);
    const Eigen::Vector3d a_w(x.d2, y.d2, z.d2);
    const Eigen::Vector3d f_b =
        q_wb.conjugate() * (a_w + Eigen::Vector3d(0.0, 0.0, IsaConstants::kG));

    AltitudeSimSample s;
    s.imu.stamp_ns = t0_ns + static_cast<int64_t>(std::llround(t * 1e9));
    s.imu.seq = static_cast<uint32_t>(k);
    s.imu.accel_mps2 = f_b + accel_bias +
                       cfg.accel_noise_mps2 * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    s.imu.gyro_rps = omega_b + gyro_bias +
                     cfg.gyro_noise_rps * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    s.imu.has_mag = false;
    if (k > 0) {
      drift_pa += cfg.baro_drift_pa_per_sqrt_s * std::sqrt(dt) * n01(rng);
    }
    const double h_abs = cfg.ground_height_m + z.v;
    double p = isa_pressure_pa(h_abs, cfg.reference_pressure_pa) + drift_pa +
               cfg.baro_noise_pa * n01(rng);
    if (cfg.baro_resolution_pa > 0.0) {
      p = std::round(p / cfg.baro_resolution_pa) * cfg.baro_resolution_pa;
    }
    s.imu.pressure_pa = p;
    s.imu.has_pressure = true;
    s.true_height_m = h_abs;
    s.true_vertical_velocity_mps = z.d1;
    s.true_vertical_accel_mps2 = z.d2;
    s.true_stationary = env.v == 0.0 && env.d1 == 0.0 && std::abs(z.d1) < 1e-12;
    out.push_back(s);
  }
  return out;
}

}  // namespace poise
