#include "poise/parallel_kf/parallel_kf.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace poise {
namespace {

constexpr double kInitVarDirection = 1e-2;  // P11 / P21 at (re)initialisation, unit-vector comps^2
constexpr double kInitVarDisturbanceUt2 = 4.0;  // P22 of KF2 at initialisation, uT^2
constexpr double kMinCos2Dip = 0.05;        // guard for the heading part of the KF2 correction

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
  p.motion_bias_tau_s = 0.0;
  p.mag_gating = false;
  p.accel_lowpass_order = 1;
  p.share_tilt_correction = false;
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
  auto need = [](bool ok, const char* what) {
    if (!ok) {
      throw std::invalid_argument(std::string("parallel_kf parameter out of range: ") + what);
    }
  };
  need(tilt.sigma_gyro_rps > 0.0, "tilt.sigma_gyro_rps must be > 0 (rad/s)");
  need(tilt.sigma_accel_mps2 > 0.0, "tilt.sigma_accel_mps2 must be > 0 (m/s^2)");
  need(tilt.c_a >= 0.0 && tilt.c_a < 1.0, "tilt.c_a must be in [0, 1)");
  need(tilt.c_a_rate_hz >= 0.0, "tilt.c_a_rate_hz must be >= 0 (Hz)");
  need(tilt.gravity_mps2 > 5.0 && tilt.gravity_mps2 < 15.0, "tilt.gravity_mps2 must be in (5, 15)");
  need(tilt.sigma_gyro_extra_rps >= 0.0, "tilt.sigma_gyro_extra_rps must be >= 0");
  need(sigma_gyro_heading_rps >= 0.0, "sigma_gyro_heading_rps must be >= 0 (0 = tilt value)");
  need(sigma_mag_ut > 0.0, "sigma_mag_ut must be > 0 (uT)");
  need(c_d >= 0.0 && c_d < 1.0, "c_d must be in [0, 1)");
  need(c_d_rate_hz >= 0.0, "c_d_rate_hz must be >= 0 (Hz)");
  need(sigma_gyro_extra_heading_rps >= 0.0, "sigma_gyro_extra_heading_rps must be >= 0");
  need(std::isnan(field_magnitude_ut) || field_magnitude_ut > 0.0, "field_magnitude_ut must be > 0 or null");
  need(std::isnan(dip_deg) || std::abs(dip_deg) < 90.0, "dip_deg must be in (-90, 90) or null");
  need(startup_s > 0.0, "startup_s must be > 0 (s)");
  need(rest_gyro_max_rps > 0.0 && rest_accel_max_mps2 > 0.0, "rest thresholds must be > 0");
  need(rest_min_s >= 0.0 && rest_filter_tau_s > 0.0, "rest times must be > 0");
  need(bias_sigma_init_rps > 0.0 && bias_sigma_rest_rps > 0.0 && bias_drift_rps > 0.0 &&
           bias_forgetting_time_s > 0.0,
       "bias_sigma_init_rps, bias_sigma_rest_rps, bias_drift_rps and bias_forgetting_time_s must be > 0");
  need(motion_bias_tau_s >= 0.0, "motion_bias_tau_s must be >= 0 (0 = off)");
  need(max_bias_rps > 0.0, "max_bias_rps must be > 0");
  need(mag_norm_tol > 0.0 && mag_dip_tol_deg > 0.0, "mag gating tolerances must be > 0");
  need(mag_max_reject_s >= 0.0, "mag_max_reject_s must be >= 0 (s, 0 = never)");
  need(mag_reacquire_s >= 0.0 && mag_reacquire_tol > 0.0, "mag_reacquire_s >= 0, mag_reacquire_tol > 0");
  need(gyro_current_weight >= 0.0 && gyro_current_weight <= 1.0, "gyro_current_weight must be in [0, 1]");
  need(accel_lowpass_tau_s >= 0.0, "accel_lowpass_tau_s must be >= 0 (s, 0 = off)");
  need(accel_lowpass_order == 1 || accel_lowpass_order == 2, "accel_lowpass_order must be 1 or 2");
  need(!share_tilt_correction || (tilt.renormalize && tilt.exact_rotation),
       "share_tilt_correction needs tilt.renormalize and tilt.exact_rotation (unit directions)");
  need(limits.max_dt_s > 0.0, "limits.max_dt_s must be > 0 (s)");
}

ParallelKf::ParallelKf(const ParallelKfParams& params) : p_(params), kf1_(params.tilt) {
  p_.validate();
  DirectionKfParams d;
  d.sigma_gyro_rps = p_.sigma_gyro_heading_rps > 0.0 ? p_.sigma_gyro_heading_rps : p_.tilt.sigma_gyro_rps;
  d.sigma_meas = p_.sigma_mag_ut;
  d.c = p_.c_d;
  d.c_rate_hz = p_.c_d_rate_hz;
  d.exact_rotation = p_.tilt.exact_rotation;
  d.renormalize = p_.tilt.renormalize;
  d.sigma_gyro_extra_rps = p_.sigma_gyro_extra_heading_rps;
  kf2_.set_params(d);
  reset();
}

void ParallelKf::reset() {
  kf1_ = TiltKf(p_.tilt);
  kf2_.reset(Eigen::Vector3d::UnitX(), kInitVarDirection, kInitVarDisturbanceUt2);
  initialized_ = false;
  heading_initialized_ = false;
  last_stamp_ns_ = -1;
  prev_gyro_.setZero();
  rejections_ = RejectCounters{};
  mag_gated_ = 0;
  mag_forced_ = 0;
  reacquired_ = 0;
  out_ = ParallelKfOutput{};
  last_q_ = Eigen::Quaterniond::Identity();
  field_m_ = std::isfinite(p_.field_magnitude_ut) ? p_.field_magnitude_ut : 0.0;
  field_dip_ = std::isfinite(p_.dip_deg) ? p_.dip_deg * kRadPerDeg : 0.0;
  field_learnt_ = std::isfinite(p_.field_magnitude_ut) && std::isfinite(p_.dip_deg);
  learn_time_s_ = 0.0;
  learn_norm_sum_ = 0.0;
  learn_dip_sum_ = 0.0;
  learn_n_ = 0;
  cand_norm_ = 0.0;
  cand_dip_ = 0.0;
  cand_stable_s_ = 0.0;
  rejected_s_ = 0.0;
  gate_dip_ = std::nan("");
  bias_.setZero();
  bias_var_ = p_.bias_sigma_init_rps * p_.bias_sigma_init_rps;
  rest_det_ = RestDetector{};
  reset_report();
}

bool ParallelKf::step(const ImuSample& s, SampleCheck& c) {
  c = check_imu_sample(s, last_stamp_ns_, p_.limits, rejections_);
  if (c.reanchor) {
    last_stamp_ns_ = s.stamp_ns;  // restart time after a gap; attitude kept
    return false;
  }
  if (!c.accept) {
    return false;
  }
  last_stamp_ns_ = s.stamp_ns;
  last_accel_ = s.accel_mps2;
  if (!initialized_) {
    initialize(s, c.mag_ok);
    return true;
  }
  const double dt = c.dt_s;
  if (p_.bias_estimation) {
    update_rest_and_bias(s.gyro_rps, s.accel_mps2, dt);
  }
  const Eigen::Vector3d gyro = s.gyro_rps - bias_;
  const Eigen::Vector3d w = prev_gyro_ + p_.gyro_current_weight * (gyro - prev_gyro_);

  // One transition for both filters: exp(-h w) or the printed first order I - h[w x] (5a), (9a)
  Eigen::Matrix3d a;
  if (p_.tilt.exact_rotation) {
    a = rot_exp(-dt * w);
  } else {
    a = -dt * skew(w);
    a.diagonal().array() += 1.0;
  }

  // KF1: tilt + external acceleration (5)-(7)
  kf1_.core().predict_with_transition(a, dt);
  const Eigen::Vector3d z_before = kf1_.up_body();
  if (p_.accel_lowpass_tau_s > 0.0) {
    // Low-pass the accelerometer in a gyro-propagated, almost inertial frame: external
    // accelerations average out there while gravity stays put; KF1 sees the filtered vector.
    r_ib_ = (r_ib_ * a.transpose()).eval();  // R_ib(k) = R_ib(k-1) exp(h w)
    if (++r_ib_steps_ >= 256) {
      r_ib_ = Eigen::Quaterniond(r_ib_).normalized().toRotationMatrix();
      r_ib_steps_ = 0;
    }
    if (p_.accel_lowpass_order == 2) {
      lp_accel_i_ = accel_bw_.step(r_ib_ * s.accel_mps2, dt);
    } else {
      lp_accel_i_ += (dt / (p_.accel_lowpass_tau_s + dt)) * (r_ib_ * s.accel_mps2 - lp_accel_i_);
    }
    kf1_.correct(r_ib_.transpose() * lp_accel_i_);
  } else {
    kf1_.correct(s.accel_mps2);
  }
  if (p_.bias_estimation && p_.motion_bias_tau_s > 0.0 && !rest_det_.rest) {
    bias_ -= kf1_.last_correction_rotvec() / p_.motion_bias_tau_s;
  }
  if (p_.share_tilt_correction && heading_initialized_) {
    // the rotation that moved sZ moves sX' too (one attitude error, two world directions)
    kf2_.set_u(rotate_by_shortest(z_before, kf1_.up_body(), kf2_.u()));  // both unit (renormalised)
  }

  // KF2: heading + magnetic disturbance (8)-(11)
  heading_step(a, s.accel_mps2, s.mag_ut, c.mag_ok, dt);

  if (p_.bias_estimation) {
    const double bn = bias_.norm();
    if (bn > p_.max_bias_rps) {
      bias_ *= p_.max_bias_rps / bn;
    }
  }
  prev_gyro_ = gyro;
  return true;
}

void ParallelKf::initialize(const ImuSample& s, bool mag_ok) {
  kf1_.reset(s.accel_mps2);  // sZ from the accelerometer
  if (mag_ok) {
    kf2_.reset(s.mag_ut.normalized(), kInitVarDirection, kInitVarDisturbanceUt2);
    heading_initialized_ = true;
    learn_field(s.accel_mps2, s.mag_ut, 0.0);
  }
  prev_gyro_ = s.gyro_rps;
  r_ib_.setIdentity();
  r_ib_steps_ = 0;
  lp_accel_i_ = s.accel_mps2;
  accel_bw_ = Butterworth2<3>(p_.accel_lowpass_tau_s > 0.0 ? p_.accel_lowpass_tau_s : 1.0);
  accel_bw_.reset(s.accel_mps2);
  initialized_ = true;
}

void ParallelKf::learn_field(const Eigen::Vector3d& /*accel*/, const Eigen::Vector3d& mag, double dt) {
  // Mean |s_M| and mean dip against the filtered up sZ over the start-up window.
  learn_norm_sum_ += mag.norm();
  learn_dip_sum_ += angle_between_vectors(kf1_.up_body(), mag) - 0.5 * kPi;
  ++learn_n_;
  learn_time_s_ += dt;
  if (!std::isfinite(p_.field_magnitude_ut)) {
    field_m_ = learn_norm_sum_ / learn_n_;
  }
  if (!std::isfinite(p_.dip_deg)) {
    field_dip_ = learn_dip_sum_ / learn_n_;
  }
  if (learn_time_s_ >= p_.startup_s) {
    field_learnt_ = true;
  }
}

void ParallelKf::update_rest_and_bias(const Eigen::Vector3d& gyro_raw, const Eigen::Vector3d& accel,
                                      double dt) {
  const RestParams rp{p_.rest_gyro_max_rps, p_.rest_accel_max_mps2, p_.rest_min_s, p_.rest_filter_tau_s};
  rest_det_.step(gyro_raw, accel, dt, rp);
  // bias Kalman filter, per component (isotropic): predict, then measure at rest
  const double v = p_.bias_drift_rps * p_.bias_drift_rps * dt / p_.bias_forgetting_time_s;
  const double var_max = p_.bias_sigma_init_rps * p_.bias_sigma_init_rps;
  bias_var_ = std::min(bias_var_ + v, var_max);
  if (rest_det_.rest) {
    // measurement noise for which continuous rest settles at bias_sigma_rest_rps^2 (= p):
    // steady state of P+ = (P + v) w / (P + v + w) at P+ = p gives w = p^2 / v + p
    const double p_rest = p_.bias_sigma_rest_rps * p_.bias_sigma_rest_rps;
    const double w = p_rest * p_rest / v + p_rest;
    const double k = bias_var_ / (bias_var_ + w);
    bias_ += k * (rest_det_.gyro_lp - bias_);
    bias_var_ *= 1.0 - k;
  }
}

void ParallelKf::heading_step(const Eigen::Matrix3d& a, const Eigen::Vector3d& accel,
                              const Eigen::Vector3d& mag, bool mag_ok, double dt) {
  out_.mag_used = false;
  if (heading_initialized_) {
    kf2_.predict_with_transition(a, dt);  // (9a), (9b), (11a)-(11e)
  }
  if (!mag_ok) {
    return;
  }
  if (!heading_initialized_) {
    kf2_.reset(mag.normalized(), kInitVarDirection, kInitVarDisturbanceUt2);
    heading_initialized_ = true;
  }
  if (!field_learnt_) {
    mag_use_ = MagUse::kLearning;
    learn_field(accel, mag, dt);
  } else if (p_.mag_gating) {
    const double norm = mag.norm();
    // sin(dip) = -sZ . s_M / |s_M| (sZ unit); |dip - alpha| <= tol  <=>  sin(dip) within
    // [sin(alpha - tol), sin(alpha + tol)] (sin is monotonic on [-90, 90] deg): no atan2 per sample.
    const Eigen::Vector3d& up = kf1_.up_body();
    const double sin_dip = -up.dot(mag) / (norm * up.norm());
    record_mag_gate(norm, sin_dip);
    if (field_dip_ != gate_dip_) {  // bounds recomputed only when the reference changes
      const double tol = p_.mag_dip_tol_deg * kRadPerDeg;
      gate_sin_lo_ = std::sin(std::max(field_dip_ - tol, -0.5 * kPi));
      gate_sin_hi_ = std::sin(std::min(field_dip_ + tol, 0.5 * kPi));
      gate_dip_ = field_dip_;
    }
    const bool disturbed = std::abs(norm - field_m_) > p_.mag_norm_tol * field_m_ ||
                           sin_dip < gate_sin_lo_ || sin_dip > gate_sin_hi_;
    if (p_.mag_soft_weight > 0.0) {
      // inflate M2 smoothly with the gate ratios (1 at the gate)
      const double rn = (norm - field_m_) / (p_.mag_norm_tol * field_m_);
      const double rd = (sin_dip - std::sin(field_dip_)) / (0.5 * (gate_sin_hi_ - gate_sin_lo_));
      mag_extra_var_ = p_.mag_soft_weight * p_.sigma_mag_ut * p_.sigma_mag_ut * (rn * rn + rd * rd);
    }
    const bool forced = disturbed && p_.mag_max_reject_s > 0.0 && rejected_s_ >= p_.mag_max_reject_s;
    if (forced) {
      mag_use_ = MagUse::kForced;
      ++mag_forced_;
    }
    if (disturbed && !forced) {
      mag_use_ = MagUse::kGated;
      ++mag_gated_;
      rejected_s_ += dt;
      // the disturbance seen through the propagated heading: sd = s_M - m sX'
      kf2_.set_e(mag - field_m_ * kf2_.u());
      // candidate for a new reference: low-passed norm/dip and how long they stayed stable
      if (p_.mag_reacquire_s > 0.0) {
        if (cand_norm_ <= 0.0) {
          cand_norm_ = norm;
          cand_dip_ = std::asin(std::max(-1.0, std::min(1.0, sin_dip)));
        }
        const double dip = std::asin(std::max(-1.0, std::min(1.0, sin_dip)));
        const double k = dt / (1.0 + dt);
        cand_norm_ += k * (norm - cand_norm_);
        cand_dip_ += k * (dip - cand_dip_);
        const bool stable = std::abs(norm - cand_norm_) < p_.mag_reacquire_tol * cand_norm_ &&
                            std::abs(dip - cand_dip_) < 0.5 * p_.mag_dip_tol_deg * kRadPerDeg;
        cand_stable_s_ = stable ? cand_stable_s_ + dt : 0.0;
        if (rejected_s_ >= p_.mag_reacquire_s && cand_stable_s_ >= p_.mag_reacquire_s) {
          field_m_ = cand_norm_;
          field_dip_ = cand_dip_;
          ++reacquired_;
          rejected_s_ = 0.0;
          cand_stable_s_ = 0.0;
          cand_norm_ = 0.0;
        }
      }
      return;
    }
    if (!disturbed) {
      rejected_s_ = 0.0;
      cand_stable_s_ = 0.0;
      cand_norm_ = 0.0;
    }
  }
  const Eigen::Vector3d x_prior = kf2_.u();
  kf2_.correct(mag, field_m_, mag_extra_var_);  // (10b), (11f)-(11h)
  mag_extra_var_ = 0.0;
  out_.mag_used = true;
  if (p_.bias_estimation && p_.motion_bias_tau_s > 0.0 && p_.motion_bias_heading && !rest_det_.rest && field_learnt_) {
    // heading part (about sZ) of the correction rotation, sX'+ x sX'- = dtheta_perp(sX')
    const Eigen::Vector3d& z = kf1_.up_body();
    const Eigen::Vector3d corr = kf2_.u().normalized().cross(x_prior.normalized());
    const double c2 = std::max(std::cos(field_dip_) * std::cos(field_dip_), kMinCos2Dip);
    bias_ -= (corr.dot(z) / c2 / p_.motion_bias_tau_s) * z;
  }
}

Eigen::Quaterniond ParallelKf::q_world_body() const {
  Eigen::Matrix3d r_body_world;  // sR = [sX sY sZ] (2), world = NWU
  const Eigen::Vector3d fwd = heading_initialized_ ? kf2_.u() : Eigen::Vector3d::UnitX();
  if (!initialized_ || !body_world_axes_from_up_forward(kf1_.up_body(), fwd, r_body_world)) {
    return last_q_;
  }
  // R_ENU_body = R_ENU_NWU sR^T: rows -sY^T, sX^T, sZ^T (x_ENU = -y_NWU, y_ENU = x_NWU)
  Eigen::Matrix3d r_enu_body;
  r_enu_body.row(0) = -r_body_world.col(1).transpose();
  r_enu_body.row(1) = r_body_world.col(0).transpose();
  r_enu_body.row(2) = r_body_world.col(2).transpose();
  Eigen::Quaterniond q(r_enu_body);
  if (q.w() < 0.0) {
    q.coeffs() = -q.coeffs();
  }
  last_q_ = q;
  return q;
}

ParallelKfOutput ParallelKf::output() const {
  ParallelKfOutput o;
  o.q_world_body = q_world_body();
  o.rpy_rad = euler_zyx_from_quat(o.q_world_body);
  // With the inertial low-pass, KF1's sa is the residual of the filtered vector: report the
  // instantaneous external acceleration s_A - g sZ instead (4).
  o.ext_accel_body_mps2 = p_.accel_lowpass_tau_s > 0.0
                              ? Eigen::Vector3d(last_accel_ - p_.tilt.gravity_mps2 * kf1_.up_body())
                              : kf1_.ext_accel_body();
  o.ext_accel_world_mps2 = o.q_world_body * o.ext_accel_body_mps2;
  o.mag_dist_body_ut = kf2_.e();
  o.mag_dist_world_ut = o.q_world_body * o.mag_dist_body_ut;
  o.mag_dist_norm_ut = o.mag_dist_body_ut.norm();
  o.gyro_bias_rps = bias_;
  o.gyro_bias_sigma_rps = std::sqrt(bias_var_);
  o.rest = rest_det_.rest;
  o.mag_used = out_.mag_used;
  o.field_learnt = field_learnt_;
  o.field_magnitude_ut = field_m_;
  o.dip_rad = field_dip_;
  return o;
}

Eigen::Matrix3d ParallelKf::attitude_covariance(const ParallelKfOutput& out) const {
  const Eigen::Matrix3d r = out.q_world_body.toRotationMatrix();
  const Eigen::Matrix3d p_up = r * tilt_covariance().topLeftCorner<3, 3>() * r.transpose();
  const Eigen::Matrix3d p_field = r * heading_covariance().topLeftCorner<3, 3>() * r.transpose();
  const double c = std::max(std::cos(out.dip_rad), 0.1);
  // A small rotation phi moves the up axis e_z by phi x e_z = (phi_y, -phi_x, 0): the tilt
  // angles are read off the up vector's x/y errors; heading from the field's east component.
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  cov(0, 0) = p_up(1, 1);
  cov(1, 1) = p_up(0, 0);
  cov(0, 1) = cov(1, 0) = -p_up(0, 1);
  cov(2, 2) = p_field(0, 0) / (c * c);
  return cov;
}

}  // namespace poise
