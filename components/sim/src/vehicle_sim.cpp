#include "poise/sim/vehicle_sim.h"

#include "poise/core/attitude.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

namespace poise {
namespace {

/// Quintic smoothstep 0 -> 1 over [t0, t0 + T].
double smooth(double t, double t0, double duration) {
  if (t <= t0) {
    return 0.0;
  }
  if (t >= t0 + duration) {
    return 1.0;
  }
  const double s = (t - t0) / duration;
  return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
}

/// One lateral-acceleration sine period (a lane change) of amplitude a over [t0, t0 + T].
double lane_change(double t, double t0, double period, double amp) {
  if (t < t0 || t > t0 + period) {
    return 0.0;
  }
  return amp * std::sin(2.0 * kPi * (t - t0) / period);
}

/// Scenario timeline: standstill, smooth acceleration to `speed`, manoeuvre of `manoeuvre_s`,
/// smooth braking, standstill. Road and path are functions of the time since the manoeuvre start.
class Scenario {
 public:
  Scenario(std::string name, double speed_mps, double manoeuvre_s)
      : name_(std::move(name)), speed_(speed_mps), manoeuvre_s_(manoeuvre_s) {
    accel_s_ = 0.75 * speed_ / kAccelMps2;  // smoothstep peak slope 1.875 / T
    brake_s_ = 0.625 * speed_ / kBrakeMps2;
    t_man_ = kStandS + accel_s_;
    t_brake_ = t_man_ + manoeuvre_s_;
    duration_ = t_brake_ + brake_s_ + kFinalStandS;
  }
  [[nodiscard]] double duration() const { return duration_; }

  [[nodiscard]] double speed(double t) const {
    return speed_ * (smooth(t, kStandS, accel_s_) - smooth(t, t_brake_, brake_s_));
  }
  /// Lateral acceleration of the path (v psi'), m/s^2.
  [[nodiscard]] double lateral(double t) const {
    const double tau = t - t_man_;
    if (name_ == "double_lane_change") {
      return lane_change(tau, 3.0, 2.5, 4.0) - lane_change(tau, 7.0, 2.5, 4.0);
    }
    if (name_ == "mountain_road") {
      const double w = smooth(tau, 0.0, 3.0) - smooth(tau, manoeuvre_s_ - 8.0, 3.0);
      return w * (2.0 * std::sin(2.0 * kPi * tau / 12.0) + 1.5 * std::sin(2.0 * kPi * tau / 7.0 + 1.0)) +
             lane_change(tau, 45.0, 2.5, 3.0) - lane_change(tau, 48.5, 2.5, 3.0);
    }
    return 0.0;
  }
  [[nodiscard]] double bank(double t) const {
    const double tau = t - t_man_;
    if (name_ == "bank_20deg") {
      return 20.0 * kRadPerDeg * smooth(tau, 3.0, 3.0);
    }
    if (name_ == "mountain_road") {
      // Banked curves: the inside of the turn is lower (left turn -> left side down -> phi < 0).
      constexpr double kBankPerMps2 = 0.03;  // rad per m/s^2 (6 deg at 3.5 m/s^2)
      const double w = smooth(tau, 0.0, 3.0) - smooth(tau, manoeuvre_s_ - 8.0, 3.0);
      return -kBankPerMps2 * w *
             (2.0 * std::sin(2.0 * kPi * tau / 12.0) + 1.5 * std::sin(2.0 * kPi * tau / 7.0 + 1.0));
    }
    return 0.0;
  }
  [[nodiscard]] double grade(double t) const {
    const double tau = t - t_man_;
    if (name_ == "hill") {
      const double g10 = std::atan(0.1);
      // Uphill is nose up (theta < 0), downhill nose down.
      return -g10 * smooth(tau, 2.0, 3.0) + 2.0 * g10 * smooth(tau, 11.0, 4.0) -
             g10 * smooth(tau, 21.0, 3.0);
    }
    if (name_ == "mountain_road") {
      const double w = smooth(tau, 0.0, 3.0) - smooth(tau, manoeuvre_s_ - 8.0, 3.0);
      return w * std::atan(0.06) * std::sin(2.0 * kPi * tau / 20.0);
    }
    return 0.0;
  }

 private:
  static constexpr double kStandS = 3.0;
  static constexpr double kFinalStandS = 6.0;
  static constexpr double kAccelMps2 = 2.5;
  static constexpr double kBrakeMps2 = 3.0;
  std::string name_;
  double speed_;
  double manoeuvre_s_;
  double accel_s_ = 0.0;
  double brake_s_ = 0.0;
  double t_man_ = 0.0;
  double t_brake_ = 0.0;
  double duration_ = 0.0;
};

Scenario make_scenario(const std::string& name) {
  constexpr double kKmh = 1.0 / 3.6;
  if (name == "double_lane_change") {
    return Scenario(name, 80.0 * kKmh, 15.0);
  }
  if (name == "bank_20deg") {
    return Scenario(name, 80.0 * kKmh, 26.0);
  }
  if (name == "hill") {
    return Scenario(name, 80.0 * kKmh, 27.0);
  }
  if (name == "mountain_road") {
    return Scenario(name, 120.0 * kKmh, 60.0);
  }
  throw std::invalid_argument("unknown vehicle scenario '" + name +
                              "' (double_lane_change, bank_20deg, hill, mountain_road)");
}

}  // namespace

const std::vector<std::string>& vehicle_sim_scenarios() {
  static const std::vector<std::string> kNames = {"double_lane_change", "bank_20deg", "hill",
                                                  "mountain_road"};
  return kNames;
}

// not split: one integration loop of the vehicle model, the sensor outputs computed beside the
// state they come from.
std::vector<VehicleSimSample> simulate_vehicle(const VehicleSimConfig& cfg) {
  if (!(cfg.rate_hz > 0.0) || !std::isfinite(cfg.rate_hz)) {
    throw std::invalid_argument("vehicle simulator: rate_hz must be > 0");
  }
  const Scenario sc = make_scenario(cfg.scenario);
  std::mt19937_64 rng(cfg.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> u11(-1.0, 1.0);
  const double yaw_bias = cfg.yaw_rate_bias_max_rps * u11(rng);

  constexpr int kSub = 10;  // internal steps per output sample
  const double dt = 1.0 / cfg.rate_hz;
  const double h = dt / kSub;
  constexpr double kDiffS = 1e-4;  // central-difference step for road-angle rates
  const VehicleModelParams& m = cfg.truth_model;
  const double mh = m.m_s_kg * m.h_s_m;
  const Eigen::Vector3d g_up(0.0, 0.0, kStandardGravityMps2);

  double psi = cfg.initial_yaw_rad;
  double phi_v = 0.0;
  double phi_v_dot = 0.0;
  double theta_v = 0.0;
  double theta_v_dot = 0.0;

  struct Kin {
    Eigen::Vector3d a_w;
    double psi_dot;
    double phi_r;
    double theta_r;
    double phi_r_dot;
    double theta_r_dot;
    double v;
    double lat;
  };
  const auto kin = [&](double t, double yaw) {
    Kin k{};
    k.v = sc.speed(t);
    const double v_dot = (sc.speed(t + kDiffS) - sc.speed(t - kDiffS)) / (2.0 * kDiffS);
    k.lat = sc.lateral(t);
    k.psi_dot = k.v > 0.1 ? k.lat / k.v : 0.0;
    k.phi_r = sc.bank(t);
    k.theta_r = sc.grade(t);
    k.phi_r_dot = (sc.bank(t + kDiffS) - sc.bank(t - kDiffS)) / (2.0 * kDiffS);
    k.theta_r_dot = (sc.grade(t + kDiffS) - sc.grade(t - kDiffS)) / (2.0 * kDiffS);
    const double ct = std::cos(k.theta_r);
    const double st = std::sin(k.theta_r);
    const double cy = std::cos(yaw);
    const double sy = std::sin(yaw);
    const Eigen::Vector3d d(ct * cy, ct * sy, -st);
    const Eigen::Vector3d dd_dpsi(-ct * sy, ct * cy, 0.0);
    const Eigen::Vector3d dd_dtheta(-st * cy, -st * sy, -ct);
    k.a_w = v_dot * d + k.v * (dd_dpsi * k.psi_dot + dd_dtheta * k.theta_r_dot);
    return k;
  };

  const auto n_out = static_cast<std::size_t>(std::floor(sc.duration() * cfg.rate_hz)) + 1U;
  std::vector<VehicleSimSample> out;
  out.reserve(n_out);
  const int64_t t0_ns = 1'000'000'000;
  for (std::size_t k = 0; k < n_out; ++k) {
    const double t = static_cast<double>(k) * dt;
    const Kin kn = kin(t, psi);
    // Sensors at t.
    const double phi = kn.phi_r + phi_v;
    const double theta = kn.theta_r + theta_v;
    const Eigen::Matrix3d r_bw = body_world_from_euler(phi, theta, psi);
    const Eigen::Vector3d f_b = r_bw * (kn.a_w + g_up);
    const double theta_dot = kn.theta_r_dot + theta_v_dot;
    const double r = -std::sin(phi) * theta_dot + std::cos(phi) * std::cos(theta) * kn.psi_dot;

    VehicleSimSample s;
    s.input.stamp_ns = t0_ns + static_cast<int64_t>(std::llround(t * 1e9));
    s.input.accel_lon_mps2 = f_b.x() + cfg.accel_noise_mps2 * n01(rng);
    s.input.accel_lat_mps2 = f_b.y() + cfg.accel_noise_mps2 * n01(rng);
    s.input.yaw_rate_rps = r + yaw_bias + cfg.yaw_rate_noise_rps * n01(rng);
    s.input.mag_ut = r_bw * cfg.mag_world_ut +
                     cfg.mag_noise_ut * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    s.input.has_mag = true;
    s.input.speed_mps = std::max(0.0, kn.v + cfg.speed_noise_mps * n01(rng));
    s.input.has_speed = true;
    s.true_roll_rad = phi;
    s.true_pitch_rad = theta;
    s.true_yaw_rad = wrap_angle(psi);
    s.road_bank_rad = kn.phi_r;
    s.road_grade_rad = kn.theta_r;
    s.true_lateral_accel_mps2 = kn.lat;
    s.true_speed_mps = kn.v;
    s.true_static = kn.v == 0.0;
    out.push_back(s);

    // Advance to t + dt: yaw and the sprung body (semi-implicit Euler on kSub steps).
    for (int j = 0; j < kSub; ++j) {
      const double tj = t + static_cast<double>(j) * h;
      const Kin kj = kin(tj, psi);
      const Eigen::Vector3d f_road =
          body_world_from_euler(kj.phi_r, kj.theta_r, psi) * (kj.a_w + g_up);
      const double phi_acc =
          (-m.k_x_nm_per_rad * phi_v - m.b_x_nms_per_rad * phi_v_dot + mh * f_road.y()) / m.i_x_kgm2;
      const double theta_acc =
          (-m.k_y_nm_per_rad * theta_v - m.b_y_nms_per_rad * theta_v_dot - mh * f_road.x()) /
          m.i_y_kgm2;
      phi_v_dot += phi_acc * h;
      theta_v_dot += theta_acc * h;
      phi_v += phi_v_dot * h;
      theta_v += theta_v_dot * h;
      psi += kj.psi_dot * h;
    }
  }
  return out;
}

}  // namespace poise
