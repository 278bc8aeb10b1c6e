#include "poise/parallel_kf/parallel_kf.h"

#include "poise/core/params_check.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace poise {
namespace {

constexpr double kInitVarDirection = 1e-2;  // P11 / P21 at (re)initialisation, unit-vector comps^2
constexpr double kInitVarDisturbanceUt2 = 4.0;  // P22 of KF2 at initialisation, uT^2
constexpr double kMinCos2Dip = 0.05;        // guard for the heading part of the KF2 correction
constexpr double kMinTiltVarRad2 = 1e-14;   // numerical guard for an inverse-variance weight
// The bias filter, and the bookkeeping of the published covariance that moves over seconds (lag
// errors, the external acceleration's reference and KF2's share, the scale error's low-passes, the
// dip's tilt variance), run once per window of this length, s (10 Hz). What they step has time
// constants of seconds: the tilt's low-pass and its twin (accel_lowpass_tau_s, 3 s by default),
// KF2's lag (10 s and more), the reference's 10 s stages, the bias filter's 100 s; 0.1 s is a
// thirtieth of the shortest (without the low-pass, rest_filter_tau_s's 0.5 s: a fifth). It was
// 0.04 s until session 25: on BROAD the means move by at most 0.01 deg between 0.04 and 0.2 s at
// 285.7, 95.2 and 40.8 Hz (docs/ESTIMATORS.md, cost), the cost by 424 instructions per sample.
constexpr double kBiasPeriodS = 0.1;
// The gravity reference of the external-acceleration term follows the accelerometer with a time
// constant of this many tilt low-pass time constants: a horizontal acceleration integrates to a
// velocity change dv, which the reference holds as about dv / (this * tau), a tenth of what the
// tilt's low-pass holds.
constexpr double kAccelReferenceTaus = 10.0;
// The largest gyro bias random walk accepted, rad/s/sqrt(s) (0.57 deg/s per sqrt(s): a bias that
// moves by degrees per second within seconds is no longer a bias a filter can learn).
constexpr double kMaxGyroBiasWalk = 0.01;
// The largest white gyro noise density accepted, rad/s/sqrt(Hz) (5.7 deg/s/sqrt(Hz): 81 deg/s per
// sample at 200 Hz, no longer a rate sensor).
constexpr double kMaxGyroNoiseDensity = 0.1;

// A low-pass's age (its samples' weighted integral of r_ib up to now, s) after a step of gain k:
// every held sample's grows by step_age (r_ib h; the weights sum to one), and the new input takes
// weight k with its own age (a bias period's mean: about step_age / 2; a reference stage's input:
// the previous stage's age).
Eigen::Matrix3d aged(const Eigen::Matrix3d& age, double k, const Eigen::Matrix3d& step_age,
                     const Eigen::Matrix3d& input_age) {
  return (1.0 - k) * (age + step_age) + k * input_age;
}

// propagate_lag_error's transition Phi over the state (tilt error x, y, heading, the Butterworth's
// second state x, y) has two entries per row that are not structurally zero (each tilt axis's two
// states; the heading and the tilt about north), Phi - I the same: a product with it is a sum of
// two products, the same to the bit whatever order a dense product adds the zeros in. lag_left
// and lag_right skip the zeros (a dense 5x5 product is 125 multiplications, these 50).
constexpr int kLagPattern[5][2] = {{0, 3}, {1, 4}, {1, 2}, {0, 3}, {1, 4}};
// Gamma B's one entry per row: the world axis of the bias error's drift each state integrates
constexpr int kLagInput[5] = {0, 1, 2, 0, 1};

template <int R, int C>
Eigen::Matrix<double, R, C> lag_left(const Eigen::Matrix<double, 5, 5>& phi, const Eigen::Matrix<double, 5, C>& x) {
  Eigen::Matrix<double, R, C> r;  // the first R rows of phi x
  for (int j = 0; j < C; ++j) {
    for (int i = 0; i < R; ++i) {
      const int a = kLagPattern[i][0];
      const int b = kLagPattern[i][1];
      r(i, j) = phi(i, a) * x(a, j) + phi(i, b) * x(b, j);
    }
  }
  return r;
}

template <int C>
Eigen::Matrix<double, 5, C> lag_right(const Eigen::Matrix<double, 5, 5>& x, const Eigen::Matrix<double, 5, 5>& phi) {
  Eigen::Matrix<double, 5, C> r;  // the first C columns of x phi^T
  for (int j = 0; j < C; ++j) {
    const int a = kLagPattern[j][0];
    const int b = kLagPattern[j][1];
    r.col(j) = x.col(a) * phi(j, a) + x.col(b) * phi(j, b);
  }
  return r;
}

}  // namespace

ParallelKfParams ParallelKfParams::paper() {
  ParallelKfParams p;
  p.tilt = TiltKfParams{};  // Table 1 noise (sigma_G 0.05 deg/s, sigma_A 0.04 m/s^2), c_a = 0.1 per step
  p.tilt.exact_rotation = false;  // (5a), (9a): first-order propagation
  p.tilt.renormalize = false;     // the paper does not renormalise sZ, sX'
  p.sigma_gyro_heading_rps = 0.0;  // KF2 uses the same sigma_G as KF1
  p.sigma_mag_ut = 0.2;             // 2 mG
  p.c_d = 0.1;
  p.c_d_rate_hz = 0.0;
  p.sigma_gyro_extra_heading_rps = 0.0;
  p.gyro_current_weight = 0.0;
  p.accel_lowpass_tau_s = 0.0;
  p.bias_estimation = false;
  p.motion_bias_sigma_rps = 0.0;
  p.mag_gating = false;
  p.accel_lowpass_order = 1;
  p.share_tilt_correction = false;
  p.mag_reference_tau_s = 0.0;
  p.mag_verify_s = 0.0;
  p.imu_delay_s = 0.0;  // the paper predicts nothing
  p.coning_correction = false;
  p.quadratic_rate = false;
  p.hard_iron = false;
  p.mag_adaptive_noise = false;
  return p;
}

ParallelKfParams ParallelKfParams::named(const std::string& name) {
  if (name == "paper") {
    return paper();
  }
  if (name == "default") {
    return defaults();
  }
  throw std::invalid_argument("unknown parallel_kf configuration '" + name +
                              "' (known: paper, default)");
}

void ParallelKfParams::validate() const {
  const ParamCheck check("parallel_kf");
  tilt.validate(check);
  check.require(tilt.gravity_mps2 > 5.0 && tilt.gravity_mps2 < 15.0, "tilt.gravity_mps2", "in (5, 15) (m/s^2)");
  check.non_negative(sigma_gyro_heading_rps, "sigma_gyro_heading_rps", "rad/s, 0 = tilt value");
  check.positive(sigma_mag_ut, "sigma_mag_ut", "uT");
  check.require(c_d >= 0.0 && c_d < 1.0, "c_d", "in [0, 1)");
  check.non_negative(c_d_rate_hz, "c_d_rate_hz", "Hz");
  check.non_negative(sigma_gyro_extra_heading_rps, "sigma_gyro_extra_heading_rps", "rad/s");
  check.positive(rest_gyro_max_rps, "rest_gyro_max_rps", "rad/s");
  check.positive(rest_accel_max_mps2, "rest_accel_max_mps2", "m/s^2");
  check.non_negative(rest_min_s, "rest_min_s", "s");
  check.positive(rest_filter_tau_s, "rest_filter_tau_s", "s");
  check.positive(bias_sigma_init_rps, "bias_sigma_init_rps", "rad/s");
  check.positive(bias_sigma_rest_rps, "bias_sigma_rest_rps", "rad/s");
  check.positive(bias_drift_rps, "bias_drift_rps", "rad/s");
  check.positive(bias_forgetting_time_s, "bias_forgetting_time_s", "s");
  check.require(std::isnan(gyro_bias_walk_rps_per_sqrt_s) ||
                    (gyro_bias_walk_rps_per_sqrt_s >= 0.0 && gyro_bias_walk_rps_per_sqrt_s <= kMaxGyroBiasWalk),
                "gyro_bias_walk_rps_per_sqrt_s", "in [0, 0.01] (rad/s/sqrt(s)), or null (not known: the design drift)");
  check.require(std::isnan(gyro_initial_bias_sd_rps) ||
                    (gyro_initial_bias_sd_rps >= 0.0 && gyro_initial_bias_sd_rps <= max_bias_rps),
                "gyro_initial_bias_sd_rps", "in [0, max_bias_rps] (rad/s), or null (not known: bias_sigma_init_rps)");
  check.require(std::isnan(gyro_noise_density_rps_per_sqrt_hz) ||
                    (gyro_noise_density_rps_per_sqrt_hz >= 0.0 && gyro_noise_density_rps_per_sqrt_hz <= kMaxGyroNoiseDensity),
                "gyro_noise_density_rps_per_sqrt_hz",
                "in [0, 0.1] (rad/s/sqrt(Hz)), or null (not known: sigma_gyro_heading_rps per sample)");
  check.non_negative(motion_bias_sigma_rps, "motion_bias_sigma_rps", "rad/s, 0 = off");
  check.positive(motion_bias_clip_rps, "motion_bias_clip_rps", "rad/s");
  check.require(motion_gyro_scale_error >= 0.0 && motion_gyro_scale_error < 1.0, "motion_gyro_scale_error", "in [0, 1)");
  check.require(std::isnan(gyro_scale_error) || (gyro_scale_error >= 0.0 && gyro_scale_error < 1.0), "gyro_scale_error",
                "in [0, 1), or null (not known: motion_gyro_scale_error)");
  check.positive(max_bias_rps, "max_bias_rps", "rad/s");
  check.require(gyro_current_weight >= 0.0 && gyro_current_weight <= 1.0, "gyro_current_weight", "in [0, 1]");
  check.require(std::isnan(imu_delay_s) || (imu_delay_s >= 0.0 && imu_delay_s <= 0.05), "imu_delay_s",
                "in [0, 0.05] (s), or null (not known: half a sample)");
  check.non_negative(accel_lowpass_tau_s, "accel_lowpass_tau_s", "s, 0 = off");
  check.require(accel_lowpass_order == 1 || accel_lowpass_order == 2, "accel_lowpass_order", "1 or 2");
  check.require(!share_tilt_correction || (tilt.renormalize && tilt.exact_rotation), "share_tilt_correction",
                "false unless tilt.renormalize and tilt.exact_rotation are true (unit directions)");
  field_gate().validate(check, {"field_magnitude_ut", "dip_deg", "startup_s", "mag_norm_tol", "mag_dip_tol_deg",
                                "mag_reference_tau_s", "mag_reacquire_s", "mag_reacquire_tol", "mag_max_reject_s",
                                "mag_verify_s"});
  poise::validate(limits, check);
  hard_iron_estimator.validate("parallel_kf hard_iron_estimator");
}

ParallelKf::ParallelKf(const ParallelKfParams& params) : p_(params) {
  p_.validate();
  gp_ = p_.field_gate();
  kf2_params_.sigma_gyro_rps = p_.sigma_gyro_heading_rps > 0.0 ? p_.sigma_gyro_heading_rps : p_.tilt.sigma_gyro_rps;
  kf2_params_.sigma_meas = p_.sigma_mag_ut;
  kf2_params_.c = p_.c_d;
  kf2_params_.c_rate_hz = p_.c_d_rate_hz;
  kf2_params_.exact_rotation = p_.tilt.exact_rotation;
  kf2_params_.renormalize = p_.tilt.renormalize;
  kf2_params_.sigma_gyro_extra_rps = p_.sigma_gyro_extra_heading_rps;
  reset();
}

void ParallelKf::reset() {
  s_ = ParallelKfState();
  s_.kf1 = TiltKf(p_.tilt);
  s_.kf2.set_params(kf2_params_);
  s_.kf2.reset(Eigen::Vector3d::UnitX(), kInitVarDirection, kInitVarDisturbanceUt2);
  s_.gate.reset(gp_);
  s_.bias_cov = Eigen::Matrix3d::Identity() * (p_.bias_sigma_init_rps * p_.bias_sigma_init_rps);
  s_.bias_err_cov = Eigen::Matrix3d::Identity() * initial_bias_err_var();
  s_.c2_dip_for = std::nan("");
  s_.hard_iron = HardIronEstimator(p_.hard_iron_estimator);
}

ParallelKf::StepRate ParallelKf::step_rate(const Eigen::Vector3d& gyro, double dt) const {
  StepRate r{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  const double h0 = s_.prev_dt_s;
  const bool coning = p_.tilt.exact_rotation && p_.coning_correction && p_.gyro_current_weight == 0.5;
  if (!coning || !p_.quadratic_rate || h0 < 0.5 * dt || h0 > 2.0 * dt) {
    r.w = s_.prev_gyro + p_.gyro_current_weight * (gyro - s_.prev_gyro);  // the line's mean
    if (coning) {
      // the rotation over the step for a rate linear between the two samples (w1 + (w2 - w1) s / h):
      // h (w1 + w2) / 2 + (h^2 / 12) w1 x w2 (the rotation vector's rate is w + theta x w / 2)
      r.coning = (dt * dt / 12.0) * s_.prev_gyro.cross(gyro);
    }
    return r;
  }
  // w(t) = a + b t + c t^2 for t in [0, dt] through w(-h0) = prev2, w(0) = prev, w(dt) = gyro; its
  // mean over the step, and its coning: (1/2) int_0^h (int_0^t w) x w(t) dt = a x b h^3 / 12 +
  // a x c h^4 / 12 + b x c h^5 / 60 (with c = 0 the line's h^2 w1 x w2 / 12)
  const Eigen::Vector3d& a = s_.prev_gyro;
  const Eigen::Vector3d c = ((gyro - a) / dt + (s_.prev2_gyro - a) / h0) / (dt + h0);
  const Eigen::Vector3d b = (gyro - a) / dt - c * dt;
  const double h3 = dt * dt * dt;
  r.w = a + (0.5 * dt) * b + (dt * dt / 3.0) * c;
  r.coning = (h3 / 12.0) * a.cross(b + dt * c) + (h3 * dt * dt / 60.0) * b.cross(c);
  return r;
}

Eigen::Matrix3d ParallelKf::transition(const StepRate& r, double dt) const {
  // One transition for both filters: exp(-h w) or the printed first order I - h[w x] (5a), (9a)
  if (p_.tilt.exact_rotation) {
    return rot_exp(-(dt * r.w + r.coning));
  }
  const Eigen::Vector3d& w = r.w;
  Eigen::Matrix3d a = -dt * skew(w);
  a.diagonal().array() += 1.0;
  return a;
}

bool ParallelKf::step(const ImuSample& s, SampleCheck& c) {
  c = check_imu_sample(s, s_.last_stamp_ns, p_.limits, s_.rejections, p_.use_magnetometer);
  if (s_.anchor.reanchor(c, s.stamp_ns, p_.limits.max_dt_s)) {
    s_.last_stamp_ns = s.stamp_ns;  // restart time after a confirmed jump; attitude kept
    s_.prev_dt_s = 0.0;             // no rate curve across the jump
    return false;
  }
  if (!c.accept) {
    return false;
  }
  s_.last_stamp_ns = s.stamp_ns;
  s_.last_accel = s.accel_mps2;
  if (!s_.initialized) {
    initialize(s, c.mag_ok);
    return true;
  }
  const double dt = c.dt_s;
  if (p_.bias_estimation) {
    const RestParams rp{p_.rest_gyro_max_rps, p_.rest_accel_max_mps2, p_.rest_min_s, p_.rest_filter_tau_s};
    s_.rest_det.step(s.gyro_rps, s.accel_mps2, dt, rp);
  }
  const Eigen::Vector3d gyro = s.gyro_rps - s_.bias;
  const StepRate rate = step_rate(gyro, dt);
  const Eigen::Vector3d& w = rate.w;
  const Eigen::Matrix3d a = transition(rate, dt);

  // KF1: tilt + external acceleration (5)-(7)
  s_.kf1.core().predict_with_transition(a, dt);
  const Eigen::Vector3d z_before = s_.kf1.up_body();
  if (p_.accel_lowpass_tau_s > 0.0 || p_.hard_iron) {
    // the gyro-only orientation (R_ib(k) = R_ib(k-1) exp(h w)): the accelerometer's low-pass frame
    // and the hard-iron estimate's rotation between its readings, from this step's transition
    s_.r_ib = (s_.r_ib * a.transpose()).eval();
    if (++s_.r_ib_steps >= 256) {
      s_.r_ib = Eigen::Quaterniond(s_.r_ib).normalized().toRotationMatrix();
      s_.r_ib_steps = 0;
    }
  }
  if (p_.accel_lowpass_tau_s > 0.0) {
    // Low-pass the accelerometer in a gyro-propagated, almost inertial frame: external
    // accelerations average out there while gravity stays put; KF1 sees the filtered vector.
    const Eigen::Vector3d accel_i = s_.r_ib * s.accel_mps2;
    const double k_lp = dt / (p_.accel_lowpass_tau_s + dt);  // first order (accel_lowpass_order 1)
    s_.lp_accel_i = p_.accel_lowpass_order == 2 ? s_.accel_bw.step(accel_i, dt)
                                                : Eigen::Vector3d(s_.lp_accel_i + k_lp * (accel_i - s_.lp_accel_i));
    s_.kf1.correct(s_.r_ib.transpose() * s_.lp_accel_i);
    external_accel_step(accel_i, dt);
  } else {
    s_.kf1.correct(s.accel_mps2);
    const double dev = s.accel_mps2.norm() - p_.tilt.gravity_mps2;
    s_.accel_dev2_lp += (dt / (p_.rest_filter_tau_s + dt)) * (dev * dev - s_.accel_dev2_lp);
  }
  s_.last_dt_s = dt;
  s_.since_mag_s += dt;
  if (gyro_scale_error() > 0.0) {
    scale_error_step(w, dt);
  }
  const bool motion_bias = p_.bias_estimation && p_.motion_bias_sigma_rps > 0.0;
  if (motion_bias) {
    s_.mb_corr += s_.kf1.last_correction_rotvec();
    if (p_.accel_lowpass_tau_s > 0.0) {
      s_.mb_rate_i += (s_.r_ib * w) * dt;  // the rate in the almost inertial frame
    } else {
      s_.mb_rate2 += w.squaredNorm() * dt;
    }
  }
  if (s_.heading_initialized) {
    // KF2 predicted to this sample's body frame (9a), (9b), (11a)-(11e), where KF1's correction is;
    // the rotation that moved sZ moves sX' too (one attitude error, two world directions)
    s_.kf2.predict_with_transition(a, dt);
    if (p_.share_tilt_correction) {
      s_.kf2.set_u(rotate_by_shortest(z_before, s_.kf1.up_body(), s_.kf2.u()));  // both unit (renormalised)
    }
  }

  // KF2: heading + magnetic disturbance (8)-(11), on the reading with the hard-iron offset removed
  const Eigen::Vector3d mag = hard_iron_corrected(s.stamp_ns, gyro, s.mag_ut, c.mag_ok);
  s_.mag_moved_at_rest = field_moved_at_rest(s.mag_ut, c.mag_ok, dt);  // the raw field: the offset turns with the body
  heading_step(mag, c.mag_ok, dt);
  s_.gate.tick(gp_, dt);
  if (p_.bias_estimation) {
    s_.mb_time += dt;
    if (s_.mb_time >= kBiasPeriodS) {
      const Eigen::Vector3d bias_before = s_.bias;
      bias_update();
      const double bn = s_.bias.norm();
      if (bn > p_.max_bias_rps) {
        s_.bias *= p_.max_bias_rps / bn;
      }
      if (p_.accel_lowpass_tau_s > 0.0) {
        external_accel_return(s_.bias - bias_before);
      }
    }
  }
  s_.prev2_gyro = s_.prev_gyro;
  s_.prev_gyro = gyro;
  s_.prev_dt_s = dt;
  return true;
}

void ParallelKf::scale_error_step(const Eigen::Vector3d& w, double dt) {
  // The attitude low-passed as the tilt (tau) and the heading (KF2's lag) follow it: a gyro scale
  // error s turns the estimate by s times the rotation away from them. The gyro-only attitude is
  // r_ib where the filter keeps it (the low-pass frame, the hard-iron estimate), else integrated
  // here. The low-passes step once per bias period on the time elapsed: their lags are seconds,
  // kBiasPeriodS 0.1 s, and only the published covariance reads them.
  if (!gyro_frame_kept()) {
    s_.q_ib = (s_.q_ib * quat_exp(dt * w)).normalized();
  }
  s_.scale_lp_s += dt;
  if (s_.scale_lp_s < kBiasPeriodS) {
    return;
  }
  const double h = s_.scale_lp_s;
  s_.scale_lp_s = 0.0;
  const Eigen::Quaterniond q_ib = gyro_attitude();
  const double tau_tilt = p_.accel_lowpass_tau_s > 0.0 ? p_.accel_lowpass_tau_s : p_.rest_filter_tau_s;
  const double tau_heading = heading_lag_s(dt);  // s (dt over KF2's gain per step)
  s_.q_lp_tilt =
      (s_.q_lp_tilt * quat_exp((h / (tau_tilt + h)) * quat_log(s_.q_lp_tilt.conjugate() * q_ib))).normalized();
  s_.q_lp_heading =
      (s_.q_lp_heading * quat_exp((h / (tau_heading + h)) * quat_log(s_.q_lp_heading.conjugate() * q_ib)))
          .normalized();
}

void ParallelKf::add_rest_heading_turn(const Eigen::Vector3d& x_prior) {
  if (!s_.rest_det.rest) {
    return;
  }
  // the turn about the vertical KF2's correction from x_prior gave (field_moved_at_rest)
  const Eigen::Vector3d& up = s_.kf1.up_body();
  const Eigen::Vector3d before = x_prior - x_prior.dot(up) * up;
  const Eigen::Vector3d after = s_.kf2.u() - s_.kf2.u().dot(up) * up;
  const double sin_part = up.dot(before.cross(after));
  const double cos_part = before.dot(after);
  // one correction turns by micro-radians: atan(x) = x - x^3 / 3 + ..., below 1e-3 x itself is
  // within 3.4e-7 of it (relative)
  s_.rest_heading_turn_rad +=
      std::abs(sin_part) < 1e-3 * cos_part ? sin_part / cos_part : std::atan2(sin_part, cos_part);
}

double ParallelKf::removed_offset_var_across_ut2() const {
  Eigen::Vector3d across;
  if (!s_.mag_corrected || !safe_normalize(s_.kf1.up_body().cross(s_.kf2.u()), across, 1e-9)) {
    return 0.0;
  }
  return across.dot(s_.hard_iron.covariance() * across);
}

bool ParallelKf::gyro_frame_kept() const { return p_.accel_lowpass_tau_s > 0.0 || p_.hard_iron; }

Eigen::Quaterniond ParallelKf::gyro_attitude() const {
  return gyro_frame_kept() ? Eigen::Quaterniond(s_.r_ib).normalized() : s_.q_ib;
}

Eigen::Vector3d ParallelKf::hard_iron_corrected(int64_t stamp_ns, const Eigen::Vector3d& gyro,
                                                const Eigen::Vector3d& mag, bool mag_ok) {
  s_.mag_corrected = false;
  s_.mag_offset_pending = false;
  if (!p_.hard_iron || !mag_ok) {
    return mag;
  }
  // the filter's gyro-only orientation: integrated once; at rest no step is taken (field_moved_at_rest)
  s_.hard_iron.update(stamp_ns, s_.r_ib, gyro, mag, p_.bias_estimation && s_.rest_det.rest);
  s_.mag_offset_pending = s_.hard_iron.pending();
  // the gate's reference, learnt at start-up on the raw field: was an offset removed now in it?
  // (a magnet on the sensor at power-on; FieldGate::hard_iron_reading)
  if (!s_.hard_iron.applied()) {
    s_.gate.hard_iron_reading(gp_, s_.hard_iron, mag, s_.kf1.up_body(), s_.last_dt_s);
    return mag;
  }
  s_.mag_corrected = true;
  ++s_.mag_corrected_count;
  const Eigen::Vector3d corrected = mag - s_.hard_iron.offset_ut();
  s_.gate.hard_iron_reading(gp_, s_.hard_iron, corrected, s_.kf1.up_body(), s_.last_dt_s);
  return corrected;
}

bool ParallelKf::field_moved_at_rest(const Eigen::Vector3d& mag, bool mag_ok, double dt) {
  // At rest the body does not turn, so neither does a world-fixed field with a constant body offset
  // seen from the gyro's frame: what moves it is a magnet attached or brought near. Judged on the
  // low-passed field (the rest detector's time constant) against the gate's norm tolerance; the
  // field when the rest began is followed with the gate's reference_tau_s (a temperature drift).
  // Held into the motion after the rest until the hard-iron estimate has judged it (hard_iron) or
  // the field is back within the tolerance of the rest's field before it moved (FieldMovedAtRest::hold).
  // (poise/core/field_gate.h FieldMovedAtRest, shared with the selective EKF)
  if (!mag_ok) {
    s_.rest_field.clear();
    return false;
  }
  if (!p_.bias_estimation || !s_.gate.learnt || !(p_.mag_norm_tol > 0.0)) {
    s_.rest_field.reset();
    return false;
  }
  const Eigen::Vector3d f = gyro_frame_kept() ? Eigen::Vector3d(s_.r_ib * mag)
                                                : Eigen::Vector3d(s_.q_ib.toRotationMatrix() * mag);
  const bool rest = s_.rest_det.rest;
  const double tol = p_.mag_norm_tol * s_.gate.m_ut;
  const bool was_held = s_.rest_field.held;
  const bool moved = s_.rest_field.step(f, rest, dt, p_.rest_filter_tau_s, gp_.reference_tau_s, tol);
  if (moved) {
    s_.gate.offset_after_startup();  // an offset removed from now on came after the start-up
  }
  // At rest the body does not turn, so the heading turns KF2's fields gave since the reading last
  // agreed with the rest's field (within the same tolerance) came from the move the low-pass has
  // only now seen: taken back, about the vertical, when it sees it. Turns from before (KF2 settling
  // a heading error the motion left) are kept.
  if (!rest) {
    s_.rest_heading_turn_rad = 0.0;
  } else if (moved && !was_held) {
    if (s_.rest_heading_turn_rad != 0.0) {
      s_.kf2.set_u(Eigen::AngleAxisd(-s_.rest_heading_turn_rad, s_.kf1.up_body()) * s_.kf2.u());
      ++s_.rest_turns_reverted;
    }
    s_.rest_heading_turn_rad = 0.0;
  } else if (!moved && (f - s_.rest_field.rest_field).norm() <= tol) {
    s_.rest_heading_turn_rad = 0.0;
  }
  return s_.rest_field.hold(moved, rest || !p_.hard_iron, s_.hard_iron.report().judged(), tol);
}

void ParallelKf::initialize(const ImuSample& s, bool mag_ok) {
  s_.kf1.reset(s.accel_mps2);  // sZ from the accelerometer
  s_.r_ib.setIdentity();         // before the hard-iron estimate's first reading takes it
  s_.r_ib_steps = 0;
  hard_iron_corrected(s.stamp_ns, s.gyro_rps, s.mag_ut, mag_ok);  // the estimate's first reading (never applied yet)
  if (mag_ok) {
    s_.kf2.reset(s.mag_ut.normalized(), kInitVarDirection, kInitVarDisturbanceUt2);
    s_.heading_initialized = true;
    if (!s_.gate.learnt) {
      s_.gate.step(gp_, s.mag_ut, s_.kf1.up_body(), 0.0);  // learning
      s_.heading_anchored = true;
    } else {
      // a configured reference: a start on a field it gates is not anchored
      s_.heading_anchored = !p_.mag_gating || !(p_.mag_verify_s > 0.0) ||
                            s_.gate.step(gp_, s.mag_ut, s_.kf1.up_body(), 0.0) != FieldVerdict::kGated;
    }
  } else {
    // 6-axis: KF2 carries north at ZYX yaw 0 for this tilt (horizontal), propagated by the gyro
    // and never corrected: the heading follows the gyro from the stated start
    const Eigen::Vector3d north = quat_tilt_yaw0(s_.kf1.up_body()).conjugate() * Eigen::Vector3d::UnitY();
    s_.kf2.reset(north, kInitVarDirection, kInitVarDisturbanceUt2);
    s_.heading_initialized = true;
    s_.heading_from_gyro = true;
  }
  s_.prev_gyro = s.gyro_rps;
  s_.lp_accel_i = s.accel_mps2;
  s_.accel_ref_stages_i = s.accel_mps2.replicate<1, 3>();
  s_.accel_ref_i = s.accel_mps2;
  s_.accel_ref_sum_i.setZero();
  s_.accel_ref_sum_s = 0.0;
  s_.accel_ref_g_ratio = 0.0;
  s_.accel_ref_c = 0.0;
  s_.accel_bw = Butterworth2<3>(p_.accel_lowpass_tau_s > 0.0 ? p_.accel_lowpass_tau_s : 1.0);
  s_.accel_bw.reset(s.accel_mps2);
  s_.accel_bw_twin = s_.accel_bw;
  s_.accel_twin_age.setZero();
  for (Eigen::Matrix3d& age : s_.accel_ref_stage_age) {
    age.setZero();
  }
  s_.accel_ref_stage_lag.setZero();
  s_.accel_ref_span_s = 0.0;
  s_.initialized = true;
}

void ParallelKf::external_accel_step(const Eigen::Vector3d& accel_i, double dt) {
  // In the almost inertial frame gravity moves only as the bias error turns the frame, so the
  // accelerometer averaged there slowly is gravity: what the tilt's low-pass holds beyond it,
  // across it, is the horizontal external acceleration that low-pass let through, which tilts the
  // estimate by itself over g (a vertical one only changes the magnitude, which the old term read).
  // The frame's turn by past bias errors is taken out of both (external_accel_return; the
  // estimate's own error from it is lag_cov's). The present bias error turns the frame at a
  // steady rate, a ramp, which the reference lags by tau as the tilt's low-pass does, so it
  // cancels in their difference (a first-order reference of 30 s lagged it by 27 s more and held
  // that as an acceleration). The low-pass is a twin of the tilt's (the tilt's own state is the
  // estimate's, never turned); a first-order one (accel_lowpass_order 1) is the tilt's itself, not
  // turned.
  // The twin steps on every sample, as the tilt's low-pass does: what it lets through of a fast
  // acceleration (vibration, tapping) reaches KF1 sample by sample. The rest steps once per bias
  // period h: the reference on the period's mean (10 s stages), the twin's age, and the moments
  // (low-passes over tau, 3 s by default, and KF2's lag, 10 s and more) on d at the period's end,
  // one draw of d per period: the same second moment as every sample's over those seconds.
  const Eigen::Vector3d& twin =
      p_.accel_lowpass_order == 2 ? s_.accel_bw_twin.step(accel_i, dt) : s_.lp_accel_i;
  s_.accel_ref_sum_i += dt * accel_i;
  s_.accel_ref_sum_s += dt;
  if (s_.accel_ref_sum_s < kBiasPeriodS) {
    return;
  }
  const double h = s_.accel_ref_sum_s;
  reference_step();
  const double k_lp = h / (p_.accel_lowpass_tau_s + h);
  // the period's samples take their weight at about h / 2, as each reference stage's input
  const Eigen::Matrix3d step_age = h * s_.r_ib;
  s_.accel_twin_age = aged(s_.accel_twin_age, k_lp, step_age, 0.5 * step_age);
  Eigen::Vector3d up;
  if (!safe_normalize(s_.accel_ref_i, up)) {
    return;
  }
  Eigen::Vector3d d = twin - s_.accel_ref_i;
  d -= d.dot(up) * up;
  d /= 1.0 - s_.accel_ref_g_ratio;  // what the reference let through in phase (reference_step)
  s_.accel_h_cov_i += k_lp * (d * d.transpose() - s_.accel_h_cov_i);
  // KF2 pulls the heading towards -tan(dip) times the tilt error about magnetic north, with its
  // lag: that error's horizontal acceleration low-passed over the lag (covariance_terms); the
  // cross moment of d and that low-pass, d h^T low-passed over tau, with h before this step
  s_.accel_h_cross_i += k_lp * (d * s_.accel_h_heading_i.transpose() - s_.accel_h_cross_i);
  const double k = h / (heading_lag_s(dt) + h);
  s_.accel_h_heading_i += k * (d - s_.accel_h_heading_i);
}

void ParallelKf::reference_step() {
  // The reference: three first-order stages of T each (the same 30 s memory as one of
  // kAccelReferenceTaus tau), combined as (1 + b s) L3 = L3 + (b / T)(L2 - L3) (s L3 = (L2 - L3) / T)
  // with b = 3 T - tau, so that a ramp lags it by 3 T - b = tau. An acceleration at w passes it as
  // b / (T^3 w^2) (3 / (T w)^2 of it against the twin's 2 / (tau w)^2: 1.2 % at T = 10 tau / 3);
  // a first-order reference passed it as 1 / (T w), as much as the twin at the tour's 0.8 Hz. It is
  // stepped once per bias period h on the period's mean (T is 10 s).
  const double tau = p_.accel_lowpass_tau_s;
  const double t_stage = kAccelReferenceTaus * tau / 3.0;
  const double h = s_.accel_ref_sum_s;
  const Eigen::Vector3d in = s_.accel_ref_sum_i / h;
  s_.accel_ref_sum_i.setZero();
  s_.accel_ref_sum_s = 0.0;
  // each stage the mean of every period it was given until there are T seconds of them (a
  // reference started on the first sample alone would hold its noise as a horizontal acceleration)
  const double t_now = std::min(s_.accel_ref_span_s, t_stage);  // each stage's time constant now
  const double k = h / (t_now + h);
  s_.accel_ref_span_s += h;
  // every held sample's integral of r_ib grows by r_ib h (the weights sum to one), then the new
  // input takes its weight with its own age (a period's mean: about h / 2): a stage's mean age is
  // its T more than its input's; the scalar lags are the same for a ramp
  const Eigen::Matrix3d step_age = h * s_.r_ib;
  Eigen::Vector3d input = in;
  Eigen::Matrix3d input_age = 0.5 * step_age;
  double input_lag = 0.5 * h;
  for (int i = 0; i < 3; ++i) {
    Eigen::Matrix3d& age = s_.accel_ref_stage_age[static_cast<size_t>(i)];
    s_.accel_ref_stages_i.col(i) += k * (input - s_.accel_ref_stages_i.col(i));
    age = aged(age, k, step_age, input_age);
    s_.accel_ref_stage_lag(i) = (1.0 - k) * (s_.accel_ref_stage_lag(i) + h) + k * input_lag;
    input = s_.accel_ref_stages_i.col(i);
    input_age = age;
    input_lag = s_.accel_ref_stage_lag(i);
  }
  // ramp lag of L3 + c (L2 - L3) is l3 - c (l3 - l2): tau for c = (l3 - tau) / (l3 - l2), which is
  // (3 T - tau) / T once the stages are full, and smaller while they are still means of their span
  const Eigen::Vector3d& lag = s_.accel_ref_stage_lag;
  const double c = lag(2) - lag(1) > 0.0 ? std::max(0.0, (lag(2) - tau) / (lag(2) - lag(1))) : 0.0;
  s_.accel_ref_c = c;
  s_.accel_ref_i = s_.accel_ref_stages_i.col(2) + c * (s_.accel_ref_stages_i.col(1) - s_.accel_ref_stages_i.col(2));
  // Well above the reference's corner an acceleration passes both low-passes as G / s^2, in phase:
  // the twin's G = 2 / tau^2 (the Butterworth's w_c^2), the reference's c / T^2 (its second stage's
  // 1 / (T^2 s^2), times c), so their difference holds (1 - G_ref / G_twin) of what the twin let
  // through (external_accel_step divides by it; at most twice, while the stages are short means)
  s_.accel_ref_g_ratio =
      p_.accel_lowpass_order == 2 && t_now > 0.0 ? std::min(0.5, c * tau * tau / (2.0 * t_now * t_now)) : 0.0;
}

void ParallelKf::external_accel_return(const Eigen::Vector3d& db) {
  // The frame r_ib was propagated with the old bias: with the new one (rate lower by db) a sample
  // taken at t' would have been turned by phi = int_t'^t r_ib db into today's frame, so a low-passed
  // vector y (its samples about y) turns by (sum of weight times that integral) db x y
  if (db.isZero(0.0)) {
    return;
  }
  s_.accel_bw_twin.transform(rot_exp(s_.accel_twin_age * db));
  for (int i = 0; i < 3; ++i) {
    s_.accel_ref_stages_i.col(i) =
        rot_exp(s_.accel_ref_stage_age[static_cast<size_t>(i)] * db) * s_.accel_ref_stages_i.col(i);
  }
  s_.accel_ref_i = s_.accel_ref_stages_i.col(2) +
                  s_.accel_ref_c * (s_.accel_ref_stages_i.col(1) - s_.accel_ref_stages_i.col(2));
}

double ParallelKf::gyro_scale_error() const {
  return std::isnan(p_.gyro_scale_error) ? p_.motion_gyro_scale_error : p_.gyro_scale_error;
}

double ParallelKf::motion_bias_noise(double dt) const {
  // process noise per step v; measurement noise w for which continuous measurement settles the
  // variance at p: steady state of P+ = (P + v) w / (P + v + w) at P+ = p gives w = p^2 / v + p
  const double v = p_.bias_drift_rps * p_.bias_drift_rps * dt / p_.bias_forgetting_time_s;
  const double p = p_.motion_bias_sigma_rps * p_.motion_bias_sigma_rps;
  return p * p / v + p;
}

void ParallelKf::bias_measure(const Eigen::Vector3d& h, double z, double w, const Eigen::Vector3d* keep,
                              MotionNoise* mn) {
  const double clip = p_.motion_bias_clip_rps;
  const double innovation = std::max(-clip, std::min(clip, z - h.dot(s_.bias)));
  const Eigen::Vector3d ph = s_.bias_cov * h;
  const double s = h.dot(ph) + w;
  Eigen::Vector3d k = ph / s;
  if (keep != nullptr) {
    // the component along *keep is not updated (Schmidt: considered, not estimated): a motion
    // measurement must not move what it cannot see, however its errors correlate with it
    k -= keep->dot(k) * *keep;
  }
  s_.bias += k * innovation;
  s_.lag_bias_cov -= (s_.lag_bias_cov * h) * k.transpose();  // b_err -= k (h^T b_err + noise)
  if (mn != nullptr) {
    // a motion measurement's noise holds -g^T d_lag / t (g = R h): E[x_lag n] = -E[x_lag d^T] g / t
    s_.lag_bias_cov += (mn->lag_x_d * (mn->r * h) / mn->t) * k.transpose();
  }
  // Joseph form (valid for any gain): P - k ph^T - ph k^T + s k k^T
  s_.bias_cov += s * k * k.transpose() - k * ph.transpose() - ph * k.transpose();
  bias_error_update(h, k, gyro_white_var(s_.mb_time), mn);
}

double ParallelKf::initial_bias_err_var() const {
  const double sd = std::isnan(p_.gyro_initial_bias_sd_rps) ? p_.bias_sigma_init_rps : p_.gyro_initial_bias_sd_rps;
  return sd * sd;
}

double ParallelKf::gyro_white_var(double t) const {
  // the mean of t / dt samples of per-sample variance density^2 / dt
  const double density = p_.gyro_noise_density_rps_per_sqrt_hz;
  if (std::isnan(density)) {
    const double sg = kf2_params_.sigma_gyro_rps;
    return sg * sg * s_.last_dt_s / t;
  }
  return density * density / t;
}

Eigen::Matrix3d ParallelKf::reference_error_cov() const {
  const ParallelKfCovarianceTerms c = covariance_terms(covariance_output(), false);  // without the terms not read
  Eigen::Matrix3d px = c.kf + c.external_accel + c.gyro_scale + c.field + c.hard_iron;
  px(2, 2) -= c.external_accel(2, 2);  // carried in full below
  px.block<2, 1>(0, 2) -= c.external_accel.block<2, 1>(0, 2);
  px.block<1, 2>(2, 0) -= c.external_accel.block<1, 2>(2, 0);
  if (s_.gate.learnt) {
    // the heading is built from sZ (2): a tilt error a about magnetic north (ENU y) turns it by
    // -tan(dip) a, and KF2 pulls it there (propagate_lag_error)
    const double tan_dip = guarded_tan_dip();
    px(2, 2) += tan_dip * tan_dip * px(1, 1);
    px(2, 1) -= tan_dip * px(1, 1);
    px(1, 2) = px(2, 1);
  }
  return px;
}

Eigen::Vector3d ParallelKf::reference_error_decay(double t) const {
  const double tau_tilt = p_.accel_lowpass_tau_s > 0.0 ? p_.accel_lowpass_tau_s : p_.rest_filter_tau_s;
  const double tau_heading = heading_lag_s(s_.last_dt_s);
  const double tilt = std::exp(-t / tau_tilt);
  return {tilt, tilt, tau_heading > 0.0 ? std::exp(-t / tau_heading) : 0.0};
}

double ParallelKf::guarded_tan_dip() const {
  if (s_.gate.dip_rad != tan_dip_for_) {  // the dip moves once per bias period at most
    tan_dip_for_ = s_.gate.dip_rad;
    tan_dip_ = std::sin(tan_dip_for_) / std::max(std::cos(tan_dip_for_), std::sqrt(kMinCos2Dip));
  }
  return tan_dip_;
}

ParallelKf::MotionNoise ParallelKf::motion_noise_window(double t, const LagIncrement& lag) const {
  // x_j = A x_{j-1} + w per axis, a = e^(-t / tau), stationary at P_x: E[x_j x_{j-1}^T] = A P_x, so
  // d = x_j - x_{j-1} has E[d d^T] = 2 P_x - A P_x - P_x A and E[d x_j^T] = P_x - P_x A; the bias
  // error (correlated with x_{j-1} by earlier windows, C) has E[b_err x_j^T] = C A and
  // E[b_err d^T] = C (A - I)
  MotionNoise mn;
  mn.t = t;
  mn.r = s_.q_world_body.toRotationMatrix();
  const Eigen::Matrix3d px = reference_error_cov();
  const Eigen::Vector3d a = reference_error_decay(t);
  const Eigen::Matrix3d pa = px * a.asDiagonal();  // P_x A
  mn.d_d = 2.0 * px - pa - pa.transpose();
  mn.d_x = px - pa;
  mn.e_x = s_.bias_err_att_cov * a.asDiagonal();
  mn.e_d = mn.e_x - s_.bias_err_att_cov;
  // and the bias's lag error's increment (independent of x): d = d_x + d_lag
  mn.d_d += lag.d_d;
  mn.e_d += lag.b_d;
  mn.lag_x_d = lag.x_d;
  return mn;
}

void ParallelKf::bias_error_update(const Eigen::Vector3d& h, const Eigen::Vector3d& k, double w_white,
                                   MotionNoise* mn) {
  // the bias error after b += k (h^T b_true + n - h^T b): M b_err - k n, M = I - k h^T, with the
  // gain the estimate used: P <- M P M^T + k k^T var(n) - M E[b_err n] k^T - k E[n b_err^T] M^T
  const Eigen::Vector3d ph = s_.bias_err_cov * h;
  double var_n = w_white;
  Eigen::Vector3d e_n = Eigen::Vector3d::Zero();  // E[b_err n]
  if (mn != nullptr) {
    // n = white - g^T d / t, g = R h the measured direction in the world
    const Eigen::Vector3d g = mn->r * h;
    var_n += g.dot(mn->d_d * g) / (mn->t * mn->t);
    e_n = -(mn->e_d * g) / mn->t;
  }
  const double s = h.dot(ph) + var_n;
  // M P M^T = P - k ph^T - ph k^T + (h^T P h) k k^T; M e_n = e_n - k (h . e_n)
  const Eigen::Vector3d me_n = e_n - k * h.dot(e_n);
  s_.bias_err_cov += s * k * k.transpose() - k * ph.transpose() - ph * k.transpose() - me_n * k.transpose() -
                     k * me_n.transpose();
  if (mn != nullptr) {
    // E[b_err+ d^T] = M E[b_err d^T] - k E[n d^T], E[n d^T] = -g^T E[d d^T] / t; the same with x_j
    const Eigen::Vector3d g = mn->r * h;
    mn->e_d -= k * (h.transpose() * mn->e_d);
    mn->e_d += k * (g.transpose() * mn->d_d) / mn->t;
    mn->e_x -= k * (h.transpose() * mn->e_x);
    mn->e_x += k * (g.transpose() * mn->d_x) / mn->t;
  } else {
    s_.bias_err_att_cov -= k * (h.transpose() * s_.bias_err_att_cov);
  }
}

void ParallelKf::motion_bias_measure(const LagIncrement& lag) {
  // KF1 turned sZ by dtheta (perpendicular to sZ) that the gyro did not explain: a bias error
  // db = b_true - b drifts the attitude at -db, so y = -sum(dtheta) / t over the window measures
  // db's horizontal part, seen through the accelerometer's low-pass. The bias itself went through
  // that low-pass too (in the inertial frame); adding back LP(R b) - R b leaves a measurement of
  // b_true. The window (kBiasPeriodS) only saves work: the bias moves over minutes.
  const double t = s_.mb_time;
  Eigen::Vector3d m = -s_.mb_corr / t;
  if (p_.accel_lowpass_tau_s > 0.0) {
    // first order with the same lag for a ramp (tau) as the accelerometer's low-pass
    const double k = t / (p_.accel_lowpass_tau_s + t);
    // a scale error s turns the attitude by s times the rotation; KF1 removes its tilt through the
    // accelerometer low-pass, so its correction rate carries s times the rate low-passed over tau
    // in the inertial frame (a rotation back and forth averages out there), not s times its rms
    s_.rate_lp_i += k * (s_.mb_rate_i / t - s_.rate_lp_i);
    s_.bias_lp_i += k * (s_.r_ib * s_.bias - s_.bias_lp_i);
    m += s_.r_ib.transpose() * s_.bias_lp_i;
  } else {
    s_.rate2_lp += (t / (p_.rest_filter_tau_s + t)) * (s_.mb_rate2 / t - s_.rate2_lp);
    m += s_.bias;
  }
  if (!s_.rest_det.rest) {  // at rest the rest measurement is better
    const Eigen::Vector3d& up = s_.kf1.up_body();
    int i_min = 0;  // the body axis least aligned with up spans the horizontal plane with it
    up.cwiseAbs().minCoeff(&i_min);
    const Eigen::Vector3d h1 = up.cross(Eigen::Vector3d::Unit(i_min)).normalized();
    const Eigen::Vector3d h2 = up.cross(h1);
    const double scale_rps = p_.motion_gyro_scale_error / p_.motion_bias_sigma_rps;
    const double w_motion = motion_bias_noise(t);
    const double rate2 = p_.accel_lowpass_tau_s > 0.0 ? s_.rate_lp_i.squaredNorm() : s_.rate2_lp;
    const double w = w_motion * (1.0 + scale_rps * scale_rps * rate2);
    MotionNoise mn = motion_noise_window(t, lag);
    bias_measure(h1, h1.dot(m), w, &up, &mn);  // the vertical part is unobservable from gravity
    bias_measure(h2, h2.dot(m), w, &up, &mn);
    if (s_.mb_head_used && s_.mb_head_trusted) {
      // heading correction rate about sZ from the accepted magnetometer updates in the window
      bias_measure(up, up.dot(s_.bias) - s_.mb_head / t, w, nullptr, &mn);
    }
    s_.bias_err_att_cov = mn.e_x;
  } else {
    // no motion measurement: x_{j-1} -> x_j decorrelates the bias error from it, E[b_err x_j^T] = C A
    s_.bias_err_att_cov = s_.bias_err_att_cov * reference_error_decay(t).asDiagonal();
  }
}

void ParallelKf::bias_update() {
  // bias Kalman filter over the window t: predict (random walk), then measure at rest (the
  // low-passed gyro) or in motion (motion_bias_measure)
  const double t = s_.mb_time;
  const LagIncrement lag = propagate_lag_error(t);
  const double v = p_.bias_drift_rps * p_.bias_drift_rps * t / p_.bias_forgetting_time_s;
  const double var_max = p_.bias_sigma_init_rps * p_.bias_sigma_init_rps;
  const double err_var_max = std::max(var_max, initial_bias_err_var());
  s_.bias_cov.diagonal().array() += v;
  // the bias estimate's real error grows by the gyro's own bias walk when the sensor says it
  const double walk = p_.gyro_bias_walk_rps_per_sqrt_s;
  s_.bias_err_cov.diagonal().array() += std::isnan(walk) ? v : walk * walk * t;
  for (int i = 0; i < 3; ++i) {  // never less certain than at start (keeps P symmetric, PSD)
    if (s_.bias_cov(i, i) > var_max) {
      const double f = std::sqrt(var_max / s_.bias_cov(i, i));
      s_.bias_cov.row(i) *= f;
      s_.bias_cov.col(i) *= f;
    }
    if (s_.bias_err_cov(i, i) > err_var_max) {
      const double f = std::sqrt(err_var_max / s_.bias_err_cov(i, i));
      s_.bias_err_cov.row(i) *= f;
      s_.bias_err_cov.col(i) *= f;
      s_.lag_bias_cov.col(i) *= f;
      s_.bias_err_att_cov.row(i) *= f;
    }
  }
  if (s_.rest_det.rest) {
    // measurement noise for which continuous rest settles at bias_sigma_rest_rps^2 (= p):
    // steady state of P+ = (P + v) w / (P + v + w) at P+ = p gives w = p^2 / v + p
    const double p_rest = p_.bias_sigma_rest_rps * p_.bias_sigma_rest_rps;
    const double w = p_rest * p_rest / v + p_rest;
    // What the window's samples really tell: the gyro's white noise (KF2's sigma_G per sample)
    // averaged over the window's t / dt samples. w above is larger by design (a smooth
    // estimate); the bias error covariance follows the gain it gives with this noise.
    const double w_true = gyro_white_var(t);
    for (int i = 0; i < 3; ++i) {  // H = I, W = w I: three scalar updates, one per axis
      const Eigen::Vector3d ph = s_.bias_cov.col(i);
      const Eigen::Vector3d k = ph / (ph(i) + w);
      s_.bias += k * (s_.rest_det.gyro_lp(i) - s_.bias(i));
      s_.lag_bias_cov -= s_.lag_bias_cov.col(i) * k.transpose();
      s_.bias_cov -= k * ph.transpose();
      bias_error_update(Eigen::Vector3d::Unit(i), k, w_true, nullptr);
    }
  }
  if (p_.motion_bias_sigma_rps > 0.0) {
    motion_bias_measure(lag);  // keeps its low-passes running at rest too
  }
  s_.mb_corr.setZero();
  s_.mb_rate2 = 0.0;
  s_.mb_rate_i.setZero();
  s_.mb_head = 0.0;
  s_.mb_time = 0.0;
  s_.mb_head_used = false;
  s_.mb_head_trusted = true;
}

ParallelKf::LagIncrement ParallelKf::propagate_lag_error(double t) {
  // Over the window t the estimate drifts at beta = R b_err (b_err = b_true - b, the gyro's error
  // after the bias is removed). The tilt is the low-passed accelerometer's, so its error about
  // each world horizontal axis is beta through (1 - H(s)) / s, H the low-pass: first order
  // 1 / (1 + tau s) gives tau / (1 + tau s), the Butterworth (w_c = sqrt(2) / tau) gives
  // (s + a1) / (s^2 + a1 s + a0), a1 = 2 / tau, a0 = 2 / tau^2 (a ramp's lag a1 / a0 = tau; the
  // error overshoots through zero after the bias is learnt). Observable form per axis:
  // e' = -a1 e + f + beta, f' = -a0 e + a1 beta. The heading integrates beta_z and keeps the share
  // lag_keep_z that the window's accepted fields left. Discretised over t (t / tau about 0.01):
  // x = Phi x + G b_err, Phi = exp(A t), G = int_0^t exp(A s) ds B R, to third order in A t.
  using Matrix5 = Eigen::Matrix<double, 5, 5>;
  using Matrix53 = Eigen::Matrix<double, 5, 3>;
  if (t != lag_t_) {  // Phi and Gamma B depend on t and the parameters only
    lag_t_ = t;
    const double tau = p_.accel_lowpass_tau_s;
    Matrix5 a = Matrix5::Zero();
    Matrix53 b = Matrix53::Zero();
    b(2, 2) = 1.0;
    if (tau > 0.0) {
      if (p_.accel_lowpass_order == 2) {
        const double a1 = 2.0 / tau;
        const double a0 = 2.0 / (tau * tau);
        for (int i = 0; i < 2; ++i) {
          a(i, i) = -a1;
          a(i, 3 + i) = 1.0;
          a(3 + i, i) = -a0;
          b(i, i) = 1.0;
          b(3 + i, i) = a1;
        }
      } else {
        a(0, 0) = a(1, 1) = -1.0 / tau;
        b(0, 0) = b(1, 1) = 1.0;
      }
    }
    const Matrix5 at = a * t;
    const Matrix5 at2 = at * at;
    lag_phi_ = Matrix5::Identity() + at + 0.5 * at2 + at2 * at / 6.0;
    Matrix5 gam = t * (Matrix5::Identity() + 0.5 * at + at2 / 6.0);
    if (!(tau > 0.0)) {  // no low-pass: KF1 follows the accelerometer (its own lag is a few samples)
      lag_phi_.topLeftCorner<2, 2>().setZero();
      gam.topLeftCorner<2, 2>().setZero();
    }
    lag_gam_b_ = gam * b;
  }
  Matrix5 phi = lag_phi_;
  Matrix53 gam_b = lag_gam_b_;
  phi.row(2) *= s_.lag_keep_z;
  gam_b.row(2) *= s_.lag_keep_z;
  if (s_.gate.learnt) {
    // The heading is built from sZ and sX' (2): with sX' exact, a tilt error a about magnetic
    // north (ENU y) turns it by -tan(dip) a. KF2 pulls sX' to the field, so the heading error
    // psi follows psi' = beta_z - (psi + tan(dip) a) / tau_2: the share of the heading's lag
    // error the fields removed is replaced by -tan(dip) times the tilt's.
    phi(2, 1) -= (1.0 - s_.lag_keep_z) * guarded_tan_dip();
  }
  // G = Gamma B R: each row of Gamma B has one entry (lag_input), so G's rows are R's, scaled
  const Eigen::Matrix3d r = s_.q_world_body.toRotationMatrix();
  Matrix53 g;
  for (int i = 0; i < 5; ++i) {
    g.row(i) = gam_b(i, kLagInput[i]) * r.row(kLagInput[i]);
  }
  const Matrix53 c = s_.lag_bias_cov;
  const Matrix53 gp = g * s_.bias_err_cov;
  const Matrix53 phi_c = lag_left<5>(phi, c);
  const Matrix5 pc = phi_c * g.transpose();
  // the increment d = (Phi - I) x + G b_err (LagIncrement, its first three rows), from the moments
  // before the step: E[d b^T] = (Phi - I) C + G B, E[y d^T] = Y X (Phi - I)^T + Y C G^T + G C^T
  // (Phi - I)^T + G B G^T for y = Y x + G b_err (Y = Phi: x_j; Y = Phi - I: d); of E[x_j d^T]
  // only the columns of d's first three rows are kept, of E[d d^T] and E[d b^T] only d's
  const Matrix5 pm = phi - Matrix5::Identity();
  const Matrix5 gpg = gp * g.transpose();
  const Matrix5 gc = g * c.transpose();
  const Matrix53 common = lag_right<3>(gc, pm) + gpg.leftCols<3>();
  const Matrix5 phi_x = lag_left<5>(phi, s_.lag_cov);
  LagIncrement inc;
  inc.x_d = lag_right<3>(phi_x, pm) + pc.leftCols<3>() + common;
  // c g^T's first three rows as a 4-row product: the rows a 5-row product sums in the same order
  const Eigen::Matrix<double, 4, 3> cg = c.topRows<4>() * g.topRows<3>().transpose();
  inc.d_d = inc.x_d.topRows<3>() - lag_right<3>(s_.lag_cov, pm).topRows<3>() - cg.topRows<3>();
  inc.b_d = (lag_left<3>(pm, c) + gp.topRows<3>()).transpose();
  Matrix5 p = lag_right<5>(phi_x, phi) + pc + pc.transpose() + gpg;
  s_.lag_cov = 0.5 * (p + p.transpose());
  s_.lag_bias_cov = phi_c + gp;
  s_.lag_keep_z = 1.0;
  return inc;
}

FieldGateParams ParallelKfParams::field_gate() const {
  FieldGateParams g;
  g.enabled = mag_gating;
  g.field_magnitude_ut = field_magnitude_ut;
  g.dip_deg = dip_deg;
  g.startup_s = startup_s;
  g.norm_tol = mag_norm_tol;
  g.dip_tol_deg = mag_dip_tol_deg;
  g.reference_tau_s = mag_reference_tau_s;
  g.reacquire_s = mag_reacquire_s;
  g.reacquire_tol = mag_reacquire_tol;
  g.max_reject_s = mag_max_reject_s;
  g.verify_s = mag_verify_s;
  return g;
}

void ParallelKf::heading_step(const Eigen::Vector3d& mag, bool mag_ok, double dt) {
  s_.mag_used = false;
  if (!mag_ok) {
    return;
  }
  const bool first_field = !s_.heading_initialized || s_.heading_from_gyro;
  if (first_field) {  // the first field: heading observable now
    s_.kf2.reset(mag.normalized(), kInitVarDirection, kInitVarDisturbanceUt2);
    s_.heading_initialized = true;
    s_.heading_from_gyro = false;
  }
  using MagUse = ParallelKfState::MagUse;
  if (!first_field && (s_.mag_moved_at_rest || s_.mag_offset_pending)) {
    // Not the Earth's field, whatever the gate would say of it at this orientation: it moved while
    // the sensor was still (a magnet attached or brought near; the heading at rest needs no
    // field), or it carries a body-fixed offset the estimate cannot remove yet (an attached
    // magnet before the rotation has shown all of it; an offset across the horizontal field
    // barely moves |s_M| or the dip, and one that reverses it can pass both). Not used, and not
    // the gate's: the field did not change for good, so its clocks (reacquire, forced use) do not run.
    s_.mag_use = s_.mag_moved_at_rest ? MagUse::kMovedAtRest : MagUse::kPending;
    s_.field_refused_s += dt;
    s_.mb_head_trusted = false;
    s_.kf2.set_e(mag - s_.gate.m_ut * s_.kf2.u());  // the disturbance seen through the propagated heading
    return;
  }
  const FieldVerdict verdict = s_.gate.step(gp_, mag, s_.kf1.up_body(), dt);
  if (verdict != FieldVerdict::kGated) {
    s_.field_refused_s = 0.0;  // a field used (or a new reference): the heading is held again
  }
  if (first_field) {
    s_.heading_anchored = verdict != FieldVerdict::kGated || !(p_.mag_verify_s > 0.0);
  }
  if (verdict == FieldVerdict::kRelearnt || (verdict == FieldVerdict::kAccepted && !s_.heading_anchored)) {
    restart_heading(mag);
    return;
  }
  if (std::isfinite(s_.gate.last_norm_ut)) {
    s_.gate_norm_ut = s_.gate.last_norm_ut;
    s_.gate_sin_dip = s_.gate.last_sin_dip;
  }
  switch (verdict) {
    case FieldVerdict::kLearning: s_.mag_use = MagUse::kLearning; break;
    case FieldVerdict::kForced: s_.mag_use = MagUse::kForced; break;
    case FieldVerdict::kGated:
      s_.mag_use = MagUse::kGated;
      s_.mb_head_trusted = false;
      // the disturbance seen through the propagated heading: sd = s_M - m sX'
      s_.kf2.set_e(mag - s_.gate.m_ut * s_.kf2.u());
      return;
    case FieldVerdict::kAccepted: break;
    case FieldVerdict::kRelearnt: break;  // restarted above
  }
  field_noise_step();
  const Eigen::Vector3d x_prior = s_.kf2.u();
  s_.kf2.correct(mag, s_.gate.m_ut, s_.mag_extra_var);  // (10b), (11f)-(11h)
  s_.mag_extra_var = 0.0;
  s_.mag_used = true;
  add_rest_heading_turn(x_prior);
  // One accepted field removes the share g = dt / lag of the heading error the gyro accumulated
  // since the heading was last held by fields (KF2's gain about the vertical), not all of it: a
  // field accepted now and then amid gated ones leaves most of it. Continuously accepted, this
  // settles at about KF2's lag.
  const double lag = heading_lag_s(dt);  // KF2's, after this correction
  const double share = std::min(1.0, dt / std::max(lag, dt));
  s_.since_mag_s *= 1.0 - share;
  s_.lag_keep_z *= 1.0 - share;
  if (s_.gate.dip_rad != s_.c2_dip_for) {  // cos^2(dip), guarded: a heading rotation shows cos(dip) in sX'
    s_.c2_dip = std::max(std::cos(s_.gate.dip_rad) * std::cos(s_.gate.dip_rad), kMinCos2Dip);
    s_.c2_dip_for = s_.gate.dip_rad;
  }
  if (s_.gate.learnt && s_.gate.m_ut > 0.0) {
    field_deviation_step(mag, lag, dt);
    if (p_.mag_gating) {  // the field-disturbance extension (off in the paper configuration)
      field_rotation_step(mag, x_prior, lag, dt);
    }
  }
  if (p_.bias_estimation && p_.motion_bias_sigma_rps > 0.0 && p_.motion_bias_heading && s_.gate.learnt) {
    if (s_.mag_use == MagUse::kForced) {
      s_.mb_head_trusted = false;  // used although gated: not a measurement of the bias
      return;
    }
    // heading part (about sZ) of the correction rotation, sX'+ x sX'- = dtheta_perp(sX'); only
    // cos(dip) of a heading rotation shows in sX'
    const bool unit = p_.tilt.renormalize && p_.tilt.exact_rotation;  // both directions are unit
    const Eigen::Vector3d corr =
        unit ? s_.kf2.u().cross(x_prior) : s_.kf2.u().normalized().cross(x_prior.normalized());
    s_.mb_head += corr.dot(s_.kf1.up_body()) / s_.c2_dip;
    s_.mb_head_used = true;
  }
}

void ParallelKf::field_noise_step() {
  // What KF2 adds to sigma_M^2 for this accepted field (mag_extra_var, uT^2 per component)
  if (p_.mag_soft_weight > 0.0 && std::isfinite(s_.gate.last_norm_ut)) {
    // inflate M2 smoothly with the gate ratios (1 at the gate)
    const double rn = s_.gate.norm_ratio(gp_);
    const double rd = s_.gate.dip_ratio();
    s_.mag_extra_var = p_.mag_soft_weight * p_.sigma_mag_ut * p_.sigma_mag_ut * (rn * rn + rd * rd);
  }
  // The removed offset's error stays in every corrected reading: its part across the field turns
  // the heading as much as the reading's own noise there, so KF2 takes it as noise (it is constant
  // in the body, so white is an approximation: the body's turning decorrelates it in the world)
  s_.mag_extra_var += removed_offset_var_across_ut2();
  s_.mag_adapt_var = 0.0;
  if (p_.mag_adaptive_noise && p_.mag_gating && !s_.mag_corrected) {
    // the heading variance the field's disturbance certainly has (v = field_rotation_var, rad^2),
    // as the per-component noise s^2 of s_M that gives KF2 that much about the vertical: a heading
    // angle is the horizontal component across the field over m cos(dip), and KF2 weighs 2 s^2 (its
    // white disturbance state doubles it; heading_lag_s), so v = 2 s^2 / (m cos(dip))^2, s^2 =
    // v (m cos(dip))^2 / 2.
    // Not for a reading with an offset removed: the offset estimate's error is the filter's own, it
    // leaves the heading an error the published covariance does not fully cover, and that error,
    // read as a disturbance, would slow the very correction that removes it (a tumbling sensor
    // with a 15 uT magnet: 0.82 -> 9.4 deg, parallel_kf_hard_iron_test)
    s_.mag_adapt_var = 0.5 * field_rotation_var() * s_.gate.m_ut * s_.gate.m_ut * s_.c2_dip;
    s_.mag_extra_var += s_.mag_adapt_var;
  }
}

void ParallelKf::field_deviation_step(const Eigen::Vector3d& mag, double lag, double dt) {
  // The heading follows the field with KF2's lag, so what moves it is the disturbance averaged
  // over that lag: its part along the reference (norm) and across it in the vertical plane
  // (dip), each low-passed over the lag, are what the gate can see of it.
  // Both low-passes, and the dip's reference, step once per bias period on the period's means of
  // the accepted fields' norm and sine of dip: the lag is 10 s and more, the period 0.1 s, and
  // the dip is one asin per period, not per sample.
  field_variances_step(dt);  // on every accepted field: field_rotation_step reads them next
  const double norm = mag.norm();
  s_.field_dev_norm_sum += dt * norm;
  s_.field_dev_sin_dip_sum += dt * (-s_.kf1.up_body().dot(mag) / norm);
  s_.field_dev_span_s += dt;
  if (s_.field_dev_span_s < kBiasPeriodS) {
    return;
  }
  const double h = s_.field_dev_span_s;
  const double m = s_.gate.m_ut;
  const double dip = std::asin(std::clamp(s_.field_dev_sin_dip_sum / h, -1.0, 1.0));
  const double k = h / (lag + h);
  s_.field_dn_lp += k * (s_.field_dev_norm_sum / h - m - s_.field_dn_lp);
  s_.field_dv_lp += k * (m * (dip - field_dip_reference(dip, h)) - s_.field_dv_lp);
  s_.field_dev_norm_sum = 0.0;
  s_.field_dev_sin_dip_sum = 0.0;
  s_.field_dev_span_s = 0.0;
}

void ParallelKf::field_rotation_step(const Eigen::Vector3d& mag, const Eigen::Vector3d& x_prior, double lag,
                                     double dt) {
  // A field whose horizontal direction is rotated by delta where the sensor moves keeps its norm
  // and dip: the gate and field_deviation_step cannot see it; the gyro can, through KF2's
  // innovation about the vertical, nu = delta - eps + n (eps the heading's error, n the modelled
  // white noise). KF2 follows the field with its lag tau (first order, H = 1 / (1 + tau s)), so
  // eps = H delta and nu = (1 - H) delta: nu's low-pass over tau, nu_lp = H (1 - H) delta, is tau
  // times the rate at which eps moves. For a delta that varies faster than tau (the sensor moving
  // through the region: a flat spectrum S0 below 1 / tau), E[eps^2] = S0 / (2 tau) and E[nu_lp^2]
  // = S0 / (4 tau) (integrals of |H|^2 and |H (1 - H)|^2), whatever S0: eps's variance is twice
  // nu_lp's. nu_lp is in quadrature with eps (it is largest while eps moves), so its square is
  // averaged over tau as well (nu2_lp). What the model explains is taken out: the white noise's
  // share, S k / (2 - k) for a step's gain k = dt / (tau + dt) and S = 2 sigma_M^2 / (m cos(dip))^2
  // (KF2's direction prior is small against it), and the attitude error's own: in a field that
  // does not turn, an error phi (world) gives nu = phi_up + tan(dip) phi_north (the field's dip
  // turns a tilt about magnetic north into a horizontal angle), and nu_lp, that low-passed, has at
  // most the variance v^T P v, v = e_up + tan(dip) e_north, P the rest of the published covariance
  // (field_heading_var, taken once per bias window with the dip's), low-passed as nu2_lp is. Like the adaptive
  // R = E[nu nu^T] - H P H^T, with P the published covariance. The estimate is untouched: only the published heading variance
  // takes 2 max(nu2_lp - model, 0) (field_rotation_var).
  const bool unit = p_.tilt.renormalize && p_.tilt.exact_rotation;  // KF2's direction is unit
  const Eigen::Vector3d& up = s_.kf1.up_body();
  const double nu = up.dot((unit ? x_prior : x_prior.normalized()).cross(mag)) / (mag.norm() * s_.c2_dip);
  const double k = dt / (lag + dt);
  s_.field_nu_lp += k * (nu - s_.field_nu_lp);
  s_.field_nu2_lp += k * (s_.field_nu_lp * s_.field_nu_lp - s_.field_nu2_lp);
  const double white = 2.0 * p_.sigma_mag_ut * p_.sigma_mag_ut / (s_.gate.m_ut * s_.gate.m_ut * s_.c2_dip);
  // the model's share passes the same two low-passes as the statistic (E[nu_lp^2] <= the low-passed
  // v^T P v: a weighted mean's square is at most the mean of the squares), so an error the
  // statistic still remembers is expected for as long as it does
  s_.field_model_lp += k * (s_.field_heading_var - s_.field_model_lp);
  s_.field_model_lp2 += k * (s_.field_model_lp - s_.field_model_lp2);
  s_.field_nu_model = white * k / (2.0 - k) + s_.field_model_lp2;
}

double ParallelKf::field_rotation_var() const {
  return 2.0 * std::max(s_.field_nu2_lp - s_.field_nu_model, 0.0);
}

void ParallelKf::field_variances_step(double dt) {
  // The published tilt variance about magnetic east changes over the bias filter's and the
  // low-pass's seconds, not from sample to sample: it is taken once per bias window (kBiasPeriodS),
  // which keeps the whole covariance (about 1800 instructions) out of the per-sample cost.
  if (!s_.initialized) {
    return;
  }
  s_.field_dip_var_age_s += dt;
  if (s_.field_dip_tilt_var >= 0.0 && s_.field_dip_var_age_s < kBiasPeriodS) {
    return;
  }
  const ParallelKfOutput out = covariance_output();
  Eigen::Vector3d east;
  if (!safe_normalize(Eigen::Vector3d::UnitZ().cross(out.q_world_body * s_.kf2.u()), east, 1e-9)) {
    return;  // no magnetic east (a vertical field): taken at the next field
  }
  const ParallelKfCovarianceTerms terms = covariance_terms(out);
  Eigen::Matrix3d cov = terms.sum();
  s_.field_dip_tilt_var = east.dot(cov * east);
  // what field_rotation_step's model expects of its innovation: the heading error and tan(dip)
  // times the tilt about magnetic north (east x up), the rotation term itself left out, and an
  // unknown heading's (a reference not yet verified: the heading is the field's all the same)
  cov -= terms.unknown_heading;
  cov(2, 2) -= field_rotation_var();
  const Eigen::Vector3d v = Eigen::Vector3d::UnitZ() + guarded_tan_dip() * east.cross(Eigen::Vector3d::UnitZ());
  s_.field_heading_var = v.dot(cov * v);
  s_.field_dip_var_age_s = 0.0;
}

double ParallelKf::field_dip_reference(double dip, double dt) {
  // A dip measured against sZ carries sZ's tilt error about magnetic east, which does not turn
  // the heading (sY = sZ x sX' keeps its direction), yet dv would read it as a disturbance: the
  // present one (against any reference) and, for a reference learnt while the tilt was poor (the
  // bias not yet known), the learning window's for good. So the term measures against the
  // accepted fields' dips, each measured against sZ as the present one is, weighted by the
  // inverse of the published tilt variance about magnetic east (each dip's error variance): the
  // minimum-variance estimate of the dip as sZ shows it, which the slow tilt error moves with
  // the present dip. It starts on the gate's reference (learnt or configured) and forgets as the
  // gate's reference follows (mag_reference_tau_s). The gate's own reference, and so the
  // estimate, is untouched.
  const uint64_t epoch = s_.gate.reference_epoch;
  if (!s_.initialized) {
    return s_.gate.dip_rad;
  }
  // each dip's error: the tilt about magnetic east (slow, shared by neighbouring dips) and the
  // magnetometer's white noise across the field in the vertical plane, sigma_M / m (independent
  // from dip to dip), so the mean does not run after the last few dips when the tilt is well known
  const double noise = p_.sigma_mag_ut / s_.gate.m_ut;
  const double var = std::max(s_.field_dip_tilt_var + noise * noise, kMinTiltVarRad2);
  if (!std::isfinite(var)) {
    return s_.gate.dip_rad;  // no usable weight (the state-health check reports the covariance)
  }
  if (!std::isfinite(s_.field_dip_ref) || s_.field_dip_epoch != epoch) {
    // the learning window's dips, as one weight: startup_s at the present variance
    s_.field_dip_ref = s_.gate.dip_rad;
    s_.field_dip_weight = gp_.startup_s / var;
    s_.field_dip_epoch = epoch;
  }
  if (gp_.reference_tau_s > 0.0) {
    if (dt != dip_forget_dt_) {  // a bias period's length: its exp when it changes
      dip_forget_dt_ = dt;
      dip_forget_ = std::exp(-dt / gp_.reference_tau_s);
    }
    s_.field_dip_weight *= dip_forget_;
  }
  const double w = dt / var;
  s_.field_dip_weight += w;
  s_.field_dip_ref += (w / s_.field_dip_weight) * (dip - s_.field_dip_ref);
  return s_.field_dip_ref;
}

void ParallelKf::restart_heading(const Eigen::Vector3d& mag) {
  s_.kf2.reset(mag.normalized(), kInitVarDirection, kInitVarDisturbanceUt2);
  s_.heading_anchored = true;
  s_.mag_use = ParallelKfState::MagUse::kRestarted;
  s_.mag_used = true;
  s_.since_mag_s = 0.0;
  s_.lag_cov.row(2).setZero();  // the heading starts again from the field: no lag error in it
  s_.lag_cov.col(2).setZero();
  s_.lag_bias_cov.row(2).setZero();
  s_.bias_err_att_cov.col(2).setZero();  // and no error the bias filter has seen the rate of
  s_.field_dn_lp = 0.0;  // deviations from the reference it replaced
  s_.field_dv_lp = 0.0;
  s_.field_dev_norm_sum = 0.0;
  s_.field_dev_sin_dip_sum = 0.0;
  s_.field_dev_span_s = 0.0;
  s_.field_nu_lp = 0.0;  // the heading starts on the field: no innovation left
  s_.field_nu2_lp = 0.0;
  s_.field_model_lp = 0.0;
  s_.field_model_lp2 = 0.0;
  s_.field_dip_ref = std::nan("");
  s_.field_dip_tilt_var = std::nan("");  // the covariance jumps with the heading: taken again
  s_.mb_head_trusted = false;  // a jump of the heading, not a measurement of the bias
  s_.q_lp_heading = gyro_attitude();  // the heading's low-passed attitude (gyro scale error) starts again
}

void ParallelKf::update_attitude() {
  // sR = [sX sY sZ] (2), world = NWU: sZ = up, sY = sZ x forward (normalised), sX = sY x sZ
  if (!s_.initialized) {
    return;
  }
  Eigen::Vector3d z = s_.kf1.up_body();
  if (!(p_.tilt.renormalize && p_.tilt.exact_rotation) && !safe_normalize(s_.kf1.up_body(), z)) {
    return;  // (renormalised and exactly rotated, sZ is unit already)
  }
  // KF2 always holds a direction once initialised (the field, or 6-axis the gyro-propagated
  // yaw-0 north); a restored state without one takes north at ZYX yaw 0 (quat_tilt_yaw0).
  const Eigen::Vector3d fwd = s_.heading_initialized
                                  ? s_.kf2.u()
                                  : Eigen::Vector3d(quat_tilt_yaw0(z).conjugate() * Eigen::Vector3d::UnitY());
  Eigen::Vector3d y;
  if (!safe_normalize(z.cross(fwd), y, 1e-9)) {
    return;
  }
  // R_ENU_body = R_ENU_NWU sR^T: rows -sY^T, sX^T, sZ^T (x_ENU = -y_NWU, y_ENU = x_NWU)
  Eigen::Matrix3d r_enu_body;
  r_enu_body.row(0) = -y.transpose();
  r_enu_body.row(1) = y.cross(z).transpose();
  r_enu_body.row(2) = z.transpose();
  Eigen::Quaterniond q(r_enu_body);
  const double delay_s = output_delay_s();
  if (delay_s > 0.0) {
    // predicted over the sensor's group delay (state untouched): q (x) exp(w d), to first order
    // [1, w d / 2] normalised (angle error (|w| d)^3 / 12: 1e-5 deg at 10 rad/s and 5 ms). q is
    // unit, so the product's norm is |[1, w d / 2]|: computed from the gyro alone, off the chain
    // of the filter's arithmetic.
    const Eigen::Vector3d half = 0.5 * delay_s * s_.prev_gyro;
    const double scale = 1.0 / std::sqrt(1.0 + half.squaredNorm());
    q = q * Eigen::Quaterniond(scale, scale * half.x(), scale * half.y(), scale * half.z());
  }
  if (q.w() < 0.0) {
    q.coeffs() = -q.coeffs();
  }
  s_.q_world_body = q;
}

double ParallelKf::output_delay_s() const {
  return std::isnan(p_.imu_delay_s) ? 0.5 * s_.last_dt_s : p_.imu_delay_s;
}

void ParallelKf::set_imu_delay_s(double delay_s) {
  ParallelKfParams p = p_;
  p.imu_delay_s = delay_s;
  p.validate();
  p_.imu_delay_s = delay_s;
}

ParallelKfOutput ParallelKf::covariance_output() const {
  ParallelKfOutput o;
  o.q_world_body = s_.q_world_body;
  o.dip_rad = s_.gate.dip_rad;
  return o;
}

ParallelKfOutput ParallelKf::output() const {
  ParallelKfOutput o;
  o.q_world_body = s_.q_world_body;
  o.rpy_rad = euler_zyx_from_quat(o.q_world_body);
  // With the inertial low-pass, KF1's sa is the residual of the filtered vector: report the
  // instantaneous external acceleration s_A - g sZ instead (4).
  o.ext_accel_body_mps2 = p_.accel_lowpass_tau_s > 0.0
                              ? Eigen::Vector3d(s_.last_accel - p_.tilt.gravity_mps2 * s_.kf1.up_body())
                              : s_.kf1.ext_accel_body();
  o.ext_accel_world_mps2 = o.q_world_body * o.ext_accel_body_mps2;
  o.mag_dist_body_ut = s_.kf2.e();
  o.mag_dist_world_ut = o.q_world_body * o.mag_dist_body_ut;
  o.mag_dist_norm_ut = o.mag_dist_body_ut.norm();
  o.gyro_bias_rps = s_.bias;
  o.gyro_bias_sigma_rps = std::sqrt(s_.bias_cov.diagonal().maxCoeff());
  o.rest = s_.rest_det.rest;
  o.mag_used = s_.mag_used;
  o.field_learnt = s_.gate.learnt;
  o.field_magnitude_ut = s_.gate.m_ut;
  o.dip_rad = s_.gate.dip_rad;
  return o;
}

bool ParallelKf::heading_unknown() const {
  // nothing bounds the heading: a provisional reference, or a start on a field the gate gated
  return s_.heading_initialized && !s_.heading_from_gyro && (!s_.gate.verified || !s_.heading_anchored);
}

HeadingStatus ParallelKf::heading_status() const {
  if (!s_.initialized || !s_.heading_initialized || s_.heading_from_gyro) {
    return HeadingStatus::kNoReference;
  }
  // no field has held the heading for mag_verify_s: gated, or refused before the gate (a field that
  // moved at rest, an offset not yet removable), in a row
  const bool long_gated =
      p_.mag_verify_s > 0.0 && s_.gate.rejected_s + s_.field_refused_s >= p_.mag_verify_s;
  return heading_unknown() || long_gated ? HeadingStatus::kUnverified : HeadingStatus::kVerified;
}

double ParallelKf::heading_lag_s(double dt) const {
  // With c_d = 0 an accepted sample is weighed against the direction noise 2 sigma_M^2 / m^2
  // (sensor noise and the white disturbance), so KF2's gain per step about the vertical is about
  // A_h m^2 / (2 sigma_M^2), A_h the variance of sX' in the horizontal direction across the field
  // (direction units); the lag is dt over that gain.
  const Eigen::Vector3d& up = s_.kf1.up_body();
  const Eigen::Vector3d up_x_field = up.cross(s_.kf2.u());
  const double n2 = up_x_field.squaredNorm();
  if (!(n2 > 1e-18)) {  // field along the vertical: no heading to hold
    return 0.0;
  }
  const double a_h = s_.kf2.variance_along(up_x_field) / n2;  // along the unit vector across sX'
  const double m = s_.gate.m_ut > 0.0 ? s_.gate.m_ut : 1.0;
  const double noise = 2.0 * (p_.sigma_mag_ut * p_.sigma_mag_ut + s_.mag_adapt_var) / (m * m);
  const double gain = std::min(1.0, a_h / noise);
  return gain > 0.0 ? dt / gain : 0.0;
}

Eigen::Matrix3d ParallelKf::attitude_covariance(const ParallelKfOutput& out) const {
  return covariance_terms(out).sum();
}

Eigen::Matrix3d ParallelKf::external_accel_covariance(const Eigen::Matrix3d& r) const {
  Eigen::Matrix3d e = Eigen::Matrix3d::Zero();
  const double g = p_.tilt.gravity_mps2;
  if (p_.accel_lowpass_tau_s > 0.0) {
    // the horizontal external acceleration a the low-pass let through (its covariance M, inertial
    // frame; external_accel_step) tilts the up vector towards it: rotation e_z x a / g
    const Eigen::Matrix3d w = r * s_.r_ib.transpose();
    const Eigen::Matrix3d m = w * s_.accel_h_cov_i * w.transpose();
    Eigen::Matrix2d tilt;
    tilt << m(1, 1), -m(0, 1), -m(0, 1), m(0, 0);
    tilt /= g * g;
    e.topLeftCorner<2, 2>() = tilt;
    if (s_.gate.learnt) {
      // the tilt about magnetic north (ENU y) is the east acceleration over g; KF2 pulls the heading
      // to -tan(dip) times it, low-passed over its lag
      const double tan_dip = guarded_tan_dip();
      const double a_north = (w * s_.accel_h_heading_i).x() / g;
      e(2, 2) = tan_dip * tan_dip * a_north * a_north;
      // One acceleration tilts the estimate now, (-a_y, a_x) / g, and pulls the heading, -tan(dip)
      // A_x / g with A low-passed over KF2's lag: their cross-covariance is the cross moment of a
      // and A times those factors. At most full correlation (a slowly varying acceleration, as a
      // start's turning frame, gives it): xc^T T^-1 xc <= the heading's share, T the tilt's block.
      const Eigen::Matrix3d x = w * s_.accel_h_cross_i * w.transpose() / (g * g);
      Eigen::Vector2d xc(tan_dip * x(1, 0), -tan_dip * x(0, 0));
      const double det = tilt.determinant();
      if (det > 0.0) {
        const double q = xc.dot(tilt.inverse() * xc);
        const double h = e(2, 2);
        if (q > h) {
          xc *= std::sqrt(h / q);
        }
        e.block<2, 1>(0, 2) = xc;
        e.block<1, 2>(2, 0) = xc.transpose();
      }
    }
  } else {
    // KF1 sees the raw accelerometer: the external acceleration's horizontal part taken as large
    // as the vertical one its magnitude shows
    e.topLeftCorner<2, 2>().diagonal().array() += s_.accel_dev2_lp / (g * g);
  }
  return e;
}

ParallelKfCovarianceTerms ParallelKf::covariance_terms(const ParallelKfOutput& out) const {
  return covariance_terms(out, true);
}

ParallelKfCovarianceTerms ParallelKf::covariance_terms(const ParallelKfOutput& out, bool lag_and_delay) const {
  ParallelKfCovarianceTerms t;
  const Eigen::Matrix3d r = out.q_world_body.toRotationMatrix();
  const Eigen::Matrix3d p_up = r * s_.kf1.direction_kf().direction_covariance() * r.transpose();
  const Eigen::Matrix3d p_field = r * s_.kf2.direction_covariance() * r.transpose();
  if (out.dip_rad != cos_dip_for_) {
    cos_dip_for_ = out.dip_rad;
    cos_dip_ = std::max(std::cos(out.dip_rad), 0.1);
  }
  const double c = cos_dip_;
  // A small rotation phi moves the up axis e_z by phi x e_z = (phi_y, -phi_x, 0): the tilt
  // angles are read off the up vector's x/y errors; heading from the field's east component.
  t.kf(0, 0) = p_up(1, 1);
  t.kf(1, 1) = p_up(0, 0);
  t.kf(0, 1) = t.kf(1, 0) = -p_up(0, 1);
  t.kf(2, 2) = p_field(0, 0) / (c * c);
  // what the KFs do not model (see the header)
  if (p_.bias_estimation && lag_and_delay) {
    // the error past bias errors left (propagated), and at least what the present bias
    // uncertainty gives over the lags (tau^2 P_b for the tilt, P_b,z t^2 for the heading): the
    // bias filter takes its motion measurements as independent of the attitude error, although
    // they are that error's own rate, so its P_b decorrelates faster than the error does
    t.bias_lag = s_.lag_cov.topLeftCorner<3, 3>();
    const Eigen::Matrix3d p_bias = r * s_.bias_err_cov * r.transpose();
    const double tau = p_.accel_lowpass_tau_s;
    const double since = s_.since_mag_s;
    const Eigen::Vector3d floor(tau * tau * p_bias(0, 0), tau * tau * p_bias(1, 1),
                                s_.heading_initialized ? p_bias(2, 2) * since * since : 0.0);
    t.bias_lag.diagonal() += (floor - s_.lag_cov.diagonal().head<3>()).cwiseMax(0.0);
  }
  t.external_accel = external_accel_covariance(r);
  if (gyro_scale_error() > 0.0) {
    // scale errors of the three gyro axes, independent, each s: the error about body axis i is
    // s times the rotation about it since the low-passed attitude
    const double s2 = gyro_scale_error() * gyro_scale_error();
    const Eigen::Quaterniond q_ib = gyro_attitude();
    const Eigen::Vector3d d_tilt = quat_log(s_.q_lp_tilt.conjugate() * q_ib);
    const Eigen::Vector3d d_heading = quat_log(s_.q_lp_heading.conjugate() * q_ib);
    const Eigen::Matrix3d p_tilt = r * (s2 * d_tilt.cwiseAbs2()).asDiagonal() * r.transpose();
    const Eigen::Matrix3d p_heading = r * (s2 * d_heading.cwiseAbs2()).asDiagonal() * r.transpose();
    t.gyro_scale.topLeftCorner<2, 2>() = p_tilt.topLeftCorner<2, 2>();
    t.gyro_scale(2, 2) = p_heading(2, 2);
  }
  if (s_.heading_initialized) {
    const double m = s_.gate.m_ut > 0.0 ? s_.gate.m_ut : 1.0;
    const double power = 0.5 * (s_.field_dn_lp * s_.field_dn_lp + s_.field_dv_lp * s_.field_dv_lp);
    // + the horizontal rotation KF2's innovations show beyond the model (field_rotation_step), rad^2
    t.field(2, 2) = power / (m * m * c * c) + field_rotation_var();
  }
  if (std::isnan(p_.imu_delay_s) && lag_and_delay) {
    // the delay not known: predicted over half a sample, the true one taken as uniform over
    // none to one sample (variance dt^2 / 12); its error turns the output about the rate axis
    const Eigen::Vector3d w_world = r * s_.prev_gyro;
    t.delay = (s_.last_dt_s * s_.last_dt_s / 12.0) * (w_world * w_world.transpose());
  }
  if (s_.mag_corrected && s_.heading_initialized) {
    // The offset removed is b's estimate: its error e (covariance P_b, body, uT^2) stays in every
    // reading the heading is built from. Only e's horizontal part across the field turns the
    // heading: with the horizontal field of magnitude B_h = m cos(dip) along the unit h and e_perp
    // = e . x (x the unit horizontal direction across it), the measured horizontal field points at
    // atan2(e_perp, B_h) ~ e_perp / B_h from h. b is constant, so KF2's averaging over its lag does
    // not reduce it: var_heading += x^T P_b x / B_h^2 (rad^2).
    const double b_h = (s_.gate.m_ut > 0.0 ? s_.gate.m_ut : 1.0) * c;
    t.hard_iron(2, 2) = removed_offset_var_across_ut2() / (b_h * b_h);
  }
  if (heading_unknown()) {
    t.unknown_heading(2, 2) = kUnknownHeadingVarRad2;
  }
  return t;
}

}  // namespace poise
