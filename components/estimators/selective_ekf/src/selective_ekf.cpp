// The selective EKF: state, prediction, the schedule of its aid sources, the history of late
// vision measurements, the output. The aid sources are in src/aid_*.cpp (shape: src/aid.h), the
// parameters' checks in params.cpp, the reports in selective_ekf_report.cpp.
#include "aid.h"

#include <algorithm>
#include <stdexcept>

namespace poise {
namespace aids = selective_ekf_aids;
using aids::kNsToS;
using aids::seconds_to_ns;

namespace {

/// Output limit: a state-output difference above 30 deg is a reset, taken at once (sin(15 deg)).
constexpr double kOutputSnapHalfSin = 0.25881904510252074;
constexpr double kChi2Dof2P95 = 5.991;  ///< the chi-square distribution's 95 % quantile, 2 degrees of freedom

/// The tilt error a first sample that passes the one-sample rest test can carry, rad^2 per tilt
/// axis. The test holds its norm within rest_accel_max_mps2 (tol) of g; an acceleration a across
/// gravity gives |f| = sqrt(g^2 + a^2), so up to a = sqrt((g + tol)^2 - g^2) passes (3.17 m/s^2
/// with 0.5), a tilt error theta with cos(theta) = g / (g + tol) (17.9 deg). The variance is the
/// one whose 95 % ellipse (2 degrees of freedom) has that radius (7.3 deg, 0.0163 rad^2). The
/// gyro's criterion bounds the rate, not the tilt (a linear acceleration turns nothing).
double rest_start_tilt_variance(const SelectiveEkfParams& p) {
  const double g = p.gravity_mps2;
  const double theta = std::acos(g / (g + p.rest_accel_max_mps2));
  return theta * theta / kChi2Dof2P95;
}

}  // namespace

Source source_of(SelectiveEkfAid a) {
  switch (a) {
    case SelectiveEkfAid::kGyro: return Source::kGyro;
    case SelectiveEkfAid::kImuQuat: return Source::kImuQuat;
    case SelectiveEkfAid::kVisionAttitude: return Source::kVisionAttitude;
    case SelectiveEkfAid::kVisionPosition: return Source::kVisionPosition;
    case SelectiveEkfAid::kAccelTilt: return Source::kAccelTilt;
    case SelectiveEkfAid::kMagHeading: return Source::kMagHeading;
    case SelectiveEkfAid::kZeroRate: return Source::kZeroRate;
    case SelectiveEkfAid::kCount: break;
  }
  return Source::kCount;
}

const char* to_string(Decision d) {
  switch (d) {
    case Decision::kNone: return "none";
    case Decision::kFused: return "fused";
    case Decision::kFusedInflated: return "fused_inflated";
    case Decision::kRejectedDisturbance: return "rejected_disturbance";
    case Decision::kRejectedQuatError: return "rejected_quat_error";
    case Decision::kRejectedNoMag: return "rejected_no_mag";
    case Decision::kRejectedGate: return "rejected_gate";
    case Decision::kRejectedBadInput: return "rejected_bad_input";
    case Decision::kRejectedTooOld: return "rejected_too_old";
    case Decision::kReset: return "reset";
    case Decision::kRejectedStateReset: return "rejected_state_reset";
    case Decision::kCount: break;
  }
  return "unknown";
}

SelectiveEkf::SelectiveEkf(const SelectiveEkfParams& params) : p_(params) {
  validate(p_);
  gp_ = heading_field_gate(p_);
  p_.q_body_camera.normalize();
  imu_delay_ns_ = std::isnan(p_.imu_delay_s) ? 0 : seconds_to_ns(p_.imu_delay_s);
  // The dip reference and input limits are shared with the Gauss-Newton source.
  if (std::isfinite(p_.dip_deg) && !std::isfinite(p_.gauss_newton.dip_deg)) {
    p_.gauss_newton.dip_deg = p_.dip_deg;
  }
  p_.gauss_newton.limits = p_.limits;
  gn_ = GaussNewton(p_.gauss_newton);
  time_offset_ = VisionTimeOffsetEstimator(aids::time_offset_params(p_));
  reset();
}

void SelectiveEkf::reset() {
  gn_.reset();
  x_ = SelectiveEkfState{};
  x_.field_gate.reset(gp_);
  x_.hard_iron = HardIronEstimator(p_.hard_iron_estimator);
  x_.P.setZero();
  const double sa = p_.init_sigma_attitude_deg * kRadPerDeg;
  x_.P.diagonal().segment<3>(kW).setConstant(p_.init_sigma_rate_rps * p_.init_sigma_rate_rps);
  x_.P.diagonal().segment<3>(kTh).setConstant(sa * sa);
  x_.P.diagonal().segment<3>(kB).setConstant(p_.init_sigma_bias_rps * p_.init_sigma_bias_rps);
  x_.P.diagonal().segment<3>(kT).setConstant(p_.init_sigma_position_m * p_.init_sigma_position_m);
  x_.P.diagonal().segment<3>(kV).setConstant(p_.init_sigma_velocity_mps *
                                              p_.init_sigma_velocity_mps);
  x_.P_err = x_.P;
  initialized_ = false;
  out_ready_ = false;
  last_imu_stamp_ns_ = -1;
  anchor_ = StampAnchor{};
  rejections_ = RejectCounters{};
  status_ = {};
  mag_ = MagStatus{};
  vc_ = VisionCounters{};
  dip_sum_rad_ = 0.0;
  norm_sum_ut_ = 0.0;
  ref_n_ = 0;
  ref_angle_rad_ = 0.5 * kPi + (std::isfinite(p_.dip_deg) ? p_.dip_deg * kRadPerDeg : 0.0);
  ref_norm_ut_ = 0.0;
  mag_.reference_ready = std::isfinite(p_.dip_deg);
  mag_.dip_deg = std::isfinite(p_.dip_deg) ? p_.dip_deg : 0.0;
  mag_.reference_angle_deg = ref_angle_rad_ * kDegPerRad;
  history_.clear();
  vision_log_.clear();
  newest_vision_capture_ns_ = -1;
  health_ = StateHealth{};
  time_offset_.reset();
}

void SelectiveEkf::set_imu_delay_s(double delay_s) {
  if (initialized_) {
    throw std::logic_error("selective_ekf: imu_delay_s is set before the first sample or after reset()");
  }
  SelectiveEkfParams p = p_;
  p.imu_delay_s = delay_s;
  validate(p);
  p_.imu_delay_s = delay_s;
  imu_delay_ns_ = std::isnan(delay_s) ? 0 : seconds_to_ns(delay_s);
}

int64_t SelectiveEkf::delay_ns(double dt_s) const {
  return std::isnan(p_.imu_delay_s) ? seconds_to_ns(0.5 * std::max(dt_s, 0.0)) : imu_delay_ns_;
}

Eigen::Quaterniond SelectiveEkf::q_world_body() const {
  return p_.output_max_correction_dps > 0.0 && out_ready_ ? out_q_ : state_output();
}

Eigen::Quaterniond SelectiveEkf::state_output() const {
  const int64_t delay = current_delay_ns();
  if (delay == 0) {
    return quat_canonical(x_.q_world_body);
  }
  const double d = static_cast<double>(delay) * kNsToS;
  return quat_canonical((x_.q_world_body * quat_exp(x_.w_rps * d)).normalized());
}

Eigen::Vector3d SelectiveEkf::position_m() const {
  return x_.t_m + x_.v_mps * (static_cast<double>(current_delay_ns()) * kNsToS);
}

Eigen::Vector3d SelectiveEkf::attitude_sigma_deg() const {
  return x_.P.diagonal().segment<3>(kTh).cwiseMax(0.0).cwiseSqrt() * kDegPerRad;
}

// ------------------------------------------------------------------------------------ process
void SelectiveEkf::predict_to(int64_t stamp_ns) {
  if (x_.stamp_ns < 0) {
    x_.stamp_ns = stamp_ns;
    return;
  }
  const double h = static_cast<double>(stamp_ns - x_.stamp_ns) * kNsToS;
  if (h <= 0.0) {
    return;
  }
  const Eigen::Vector3d wh = x_.w_rps * h;
  const Eigen::Quaterniond dq = quat_exp(wh);
  x_.q_world_body = (x_.q_world_body * dq).normalized();  // q <- q (x) exp(w h / 2) (3)
  x_.t_m += x_.v_mps * h;                                  // t <- t + v h (3)
  // P <- F P F^T + Q (4), F applied by blocks: F P F^T = F (F P)^T for symmetric P.
  // F is block-diagonal between [w, th, b] and [t, v]; while P has no cross-covariance between
  // the two (no lever-arm position fix yet, x_.coupled false) each block is propagated alone.
  const Eigen::Matrix3d a = dq.toRotationMatrix().transpose();  // J_dth'_dth = Exp(w h)^T
  const Eigen::Matrix3d b = so3_right_jacobian(wh) * h;         // J_dth'_dw
  // The accelerometer low-pass's frame turns with the same rate (its error is the prediction's
  // own): de' = de + R_ib J_r(w h) h dw with R_ib after the step.
  x_.pre.q_ib = (x_.pre.q_ib * dq).normalized();
  const Eigen::Matrix3d r_ib = x_.pre.q_ib.toRotationMatrix();
  const Eigen::Matrix3d e_w = r_ib * b;  // J_de'_dw
  propagate_ext_accel_error(a, b, e_w, h);  // (by the same F)
  if (x_.coupled) {
    auto apply_f = [&](const Mat& m) {
      Mat out = m;
      out.middleRows<3>(kTh) = a * m.middleRows<3>(kTh) + b * m.middleRows<3>(kW);
      out.middleRows<3>(kE) += e_w * m.middleRows<3>(kW);
      out.middleRows<3>(kT) += h * m.middleRows<3>(kV);
      return out;
    };
    for (Mat* pm : {&x_.P, &x_.P_err}) {
      const Mat fp = apply_f(*pm);
      const Mat fpf = apply_f(fp.transpose());
      *pm = 0.5 * (fpf + fpf.transpose());
    }
  } else {
    using Mat6 = Eigen::Matrix<double, 6, 6>;
    using MatA = Eigen::Matrix<double, kAttN, kAttN>;
    auto apply_att = [&](const MatA& m) {
      MatA out = m;
      out.middleRows<3>(kTh) = a * m.middleRows<3>(kTh) + b * m.middleRows<3>(kW);
      out.middleRows<3>(kE) += e_w * m.middleRows<3>(kW);
      return out;
    };
    for (Mat* pm : {&x_.P, &x_.P_err}) {
      const MatA att = pm->topLeftCorner<kAttN, kAttN>();  // [w, th, b, e]: th' = a th + b w, e' = e + R_ib b w
      const MatA fa = apply_att(att);
      const MatA fpf = apply_att(fa.transpose());
      pm->topLeftCorner<kAttN, kAttN>() = 0.5 * (fpf + fpf.transpose());  // exactly symmetric
      Mat6 tr = pm->bottomRightCorner<6, 6>();  // [t, v]: t' = t + h v
      tr.topRows<3>() += h * tr.bottomRows<3>();
      tr.leftCols<3>() += h * tr.rightCols<3>();
      pm->bottomRightCorner<6, 6>() = tr;
    }
  }
  const double qw = p_.sigma_angular_accel * p_.sigma_angular_accel * h;
  const double qth = p_.sigma_attitude_walk * p_.sigma_attitude_walk * h;
  const double qv = p_.sigma_linear_accel * p_.sigma_linear_accel * h;
  const double qb = p_.sigma_bias_walk * p_.sigma_bias_walk * h;
  // Q of the continuous white-noise models over h: [q h, q h^2/2; q h^2/2, q h^3/3] for each
  // (rate, attitude) and (velocity, position) pair, the attitude's q h^3/3 (with the walk) given
  // as s_th. The cross terms let the gyro row correct the attitude integrated with the previous
  // rate (trapezoid-like, no one-sample lag).
  const double qc_w = qw * h / 2.0;
  const double qc_v = qv * h / 2.0;
  auto add_q = [&](Mat& m, double s_th, double q_b) {
    for (int i = 0; i < 3; ++i) {
      m(kW + i, kW + i) += qw;
      m(kTh + i, kTh + i) += s_th;
      m(kW + i, kTh + i) += qc_w;
      m(kTh + i, kW + i) += qc_w;
      m(kB + i, kB + i) += q_b;
      m(kV + i, kV + i) += qv;
      m(kT + i, kT + i) += qv * h * h / 3.0;
      m(kV + i, kT + i) += qc_v;
      m(kT + i, kV + i) += qc_v;
    }
    // the low-pass's frame integrates the same rate and attitude noise (body n), as R_ib n:
    // E[n n^T] = s I gives Q_ee = s I, Q_th,e = s R_ib^T, Q_w,e = c R_ib^T
    m.block<3, 3>(kE, kE) += s_th * Eigen::Matrix3d::Identity();
    m.block<3, 3>(kTh, kE) += s_th * r_ib.transpose();
    m.block<3, 3>(kE, kTh) += s_th * r_ib;
    m.block<3, 3>(kW, kE) += qc_w * r_ib.transpose();
    m.block<3, 3>(kE, kW) += qc_w * r_ib;
  };
  add_q(x_.P, qth + qw * h * h / 3.0, qb);
  // The estimate's error: the same, but a gyro sample is the rate's mean over its interval,
  // centred on the state's time, so the attitude's increment between two state times is the
  // trapezoid of the two rates, h (w_k-1 + w_k) / 2, up to the halves of the two intervals'
  // paths, which telescope (over any run of samples only its two ends remain: a bounded error,
  // not a noise that accumulates). The rate's noise n (q h) enters the attitude as (h / 2) n,
  // which the gyro row sees: [q h, q h^2/2; q h^2/2, q h^3/4] and no residual. P's q h^3 / 3
  // leaves q h^3 / 12 per interval that no row sees (a gyro sampling the rate at instants).
  // The sensor's own figures where known (update.h): the attitude's noise is then the gyro's
  // alone (through the gyro row), the bias walks by the gyro's own walk.
  add_q(x_.P_err, aids::err_attitude_walk2(p_) * h + qw * h * h / 4.0, aids::err_bias_walk2(p_) * h);
  x_.stamp_ns = stamp_ns;
}

// ------------------------------------------------------------------------------------ aiding
// The schedule of the aid sources (one file each, src/aid.h): which run at a step, in which order.
SourceStatus& SelectiveEkf::status_of(SelectiveEkfAid a) { return status_[static_cast<size_t>(a)]; }

void SelectiveEkf::process_imu(const ImuInput& in_raw, bool first_pass) {
  ImuInput in = in_raw;
  preprocess(in);
  if (p_.imu_measurement == ImuMeasurement::kSplit) {
    field_offsets(in);
  }
  const int64_t now = in.stamp_ns;
  const aids::AidContext c{x_, p_, first_pass};
  aids::aid_gyro(c, in, status_of(SelectiveEkfAid::kGyro));
  aids::aid_zero_rate(c, in, status_of(SelectiveEkfAid::kZeroRate));
  // The predicted up axis is only as good as the tilt: in the paper's quaternion mode without a
  // recent vision fix the tilt is carried by the gyro alone (q_imu gated), and a drifting tilt
  // would keep the test failing (self-locking), so the raw accelerometer is used there.
  const bool anchored = x_.last_vision_fused_ns >= 0 &&
                        now - x_.last_vision_fused_ns <= seconds_to_ns(p_.vision_anchor_s);
  aids::MagTrust mag{mag_, gp_, ref_angle_rad_, ref_norm_ut_, FieldVerdict::kAccepted};
  bool aided = false;
  if (p_.imu_measurement == ImuMeasurement::kQuaternion) {
    aids::aid_imu_quat(c, in, anchored, mag, status_of(SelectiveEkfAid::kImuQuat));
  } else if (x_.last_aiding_ns < 0 || now - x_.last_aiding_ns >= seconds_to_ns(p_.aiding_period_s)) {
    // Tilt and heading are spectral densities: fusing them every aiding_period_s with the variance
    // of the elapsed interval carries the same information as every sample (their bandwidth is
    // far below the aiding rate) at a fraction of the cost.
    // Tilt noise density: configured, or the one that makes the tilt's time constant the
    // low-pass's (with the sample interval: the gyro's share of the attitude noise)
    in.tilt_sigma = std::isnan(p_.sigma_tilt_rad_sqrt_s)
                        ? p_.accel_lowpass_tau_s * std::sqrt(p_.sigma_attitude_walk * p_.sigma_attitude_walk +
                                                             p_.sigma_gyro_rps * p_.sigma_gyro_rps * std::max(in.dt_s, 0.0))
                        : p_.sigma_tilt_rad_sqrt_s;
    // (bounded: across a re-anchored time gap nothing was integrated)
    if (x_.last_aiding_ns >= 0) {
      in.dt_s = std::min(static_cast<double>(now - x_.last_aiding_ns) * kNsToS,
                         p_.aiding_period_s + in.dt_s);
    }
    x_.last_aiding_ns = now;
    aids::aid_accel_tilt(c, in, status_of(SelectiveEkfAid::kAccelTilt));
    aids::aid_mag_heading(c, in, anchored, mag, status_of(SelectiveEkfAid::kMagHeading));
    aided = true;
  }
  track_unmodelled(in_raw, aided, in.dt_s);
}

void SelectiveEkf::process_vision(const VisionPose& v, bool first_pass) {
  if (x_.pre.start_pending) {
    // a start at rest not yet settled (settle_start): its tilt bound joins P_err, which the
    // frame's rows shrink by their own gain (the low-pass's part stays until it forgets it)
    add_start_bound(1.0);
  }
  const aids::AidContext c{x_, p_, first_pass};
  const aids::VisionMeasurement m = aids::vision_measurement(p_, v);
  aids::aid_vision_attitude(c, m, status_of(SelectiveEkfAid::kVisionAttitude));
  aids::aid_vision_position(c, m, status_of(SelectiveEkfAid::kVisionPosition));  // after: uses the new attitude
}

// ------------------------------------------------------------------------------------ inputs
void SelectiveEkf::learn_reference(const ImuSample& s) {
  if (ref_n_ >= p_.startup_samples) {
    return;
  }
  dip_sum_rad_ += angle_between_vectors(s.mag_ut, s.accel_mps2);
  norm_sum_ut_ += s.mag_ut.norm();
  ++ref_n_;
  if (ref_n_ == p_.startup_samples) {
    ref_norm_ut_ = norm_sum_ut_ / ref_n_;
    if (!std::isfinite(p_.dip_deg)) {
      ref_angle_rad_ = dip_sum_rad_ / ref_n_;  // theta_ref = 90 deg + dip
      mag_.dip_deg = ref_angle_rad_ * kDegPerRad - 90.0;
      mag_.reference_angle_deg = ref_angle_rad_ * kDegPerRad;
    }
    mag_.reference_ready = true;
  }
}

// The external acceleration's error (SelectiveEkfState::ext_accel_error, the accelerometer's
// figure known) over a prediction, by P's F: th' = a th + b w, e' = e + e_w w, t' = t + h v.
void SelectiveEkf::propagate_ext_accel_error(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b,
                                             const Eigen::Matrix3d& e_w, double h) {
  if (!aids::accel_noise_known(p_)) {
    return;
  }
  Vec& z = x_.ext_accel_error;
  z.segment<3>(kE) += e_w * z.segment<3>(kW);
  z.segment<3>(kTh) = a * z.segment<3>(kTh) + b * z.segment<3>(kW);
  z.segment<3>(kT) += h * z.segment<3>(kV);
}

// The external acceleration the low-pass lets through, as the accelerometer shows it
// (SelectiveEkfState::ext_accel_error): `deviation` d is the sample less the low-pass (its frame),
// k the low-pass's gain at this sample. P_err's model of the low-pass's noise (preprocess:
// e <- (1 - k) e + k n_rot) driven by this sample's deviation d, n_rot = d x u / |lp| (the turn
// of the low-passed vector it causes), instead of the noise's statistics. What P_err holds
// already is left out: the deviation's slow part (its low-pass over the same tau: the low-pass's
// lag behind a frame that turns with the bias error) and, across u, what the noise can explain
// (shrunk by the noise's 95 % radius, 2 degrees of freedom, 5.991 N^2 / dt): a sensor at rest
// drives none.
void SelectiveEkf::drive_ext_accel_error(const Eigen::Vector3d& deviation, double k, double dt_s) {
  SelectiveEkfPreState& pre = x_.pre;
  const double g = pre.lp_accel_i.norm();
  Vec& z = x_.ext_accel_error;
  z.segment<3>(kE) *= 1.0 - k;
  const Eigen::Vector3d fast = deviation - pre.deviation_lp;
  pre.deviation_lp += k * fast;
  if (g > 0.0) {
    const Eigen::Vector3d across = fast.cross(pre.lp_accel_i / g);
    const double n = p_.accel_noise_density_mps2_per_sqrt_hz;
    const double radius = std::sqrt(kChi2Dof2P95 * n * n / dt_s);
    const double size = across.norm();
    if (size > radius) {
      z.segment<3>(kE) += (k / g) * (1.0 - radius / size) * across;
    }
  }
}

// A start at rest with the accelerometer's noise known (preprocess) took its first sample's tilt
// as known up to the noise, publishing the rest test's tilt bound meanwhile. The samples after it
// settle whether that sample carried external acceleration. Both the attitude and the low-pass
// started on it, so its error stays in both (e = dth: the tilt rows see nothing of it) until the
// low-pass forgets it over accel_lowpass_tau_s.
//   A sample outside the rest test (|deviation from the low-pass| above rest_accel_max_mps2, or
//   |gyro - bias| above rest_gyro_max_rps) within rest_filter_tau_s of the start: the sensor was
//   not at rest, and the first sample may have carried the bound's acceleration: P_err takes the
//   bound (a transient at the first sample shows at the second as its negative; a push, when it
//   ends).
//   The rest test held for rest_filter_tau_s (the rest detector's time constant, over which it
//   tells motion from rest): a later sample at rest deviates from the first by minus the first's
//   acceleration, a step from the second sample on; the frame's turn with a bias not yet learnt
//   adds a ramp (g x db t, P_err's own). The step is the intercept c of the straight line fitted
//   to the deviations over the window (weights dt, each sample's noise N^2 / dt per axis: the
//   line's variance at s is N^2 (S2 - 2 s S1 + s^2 S0) / (S0 S2 - S1^2)); it holds the first
//   sample's noise too (N^2 / dt, which P_err has: start_noise_pending). An acceleration that
//   ends within the window is a step later than the second sample, which the line's end value
//   covers (a step at a fraction f of the window: (1 - f)(1 + 3 f) of it, at least all of it
//   up to f = 2/3; the intercept only (1 - f)(1 - 3 f)). The larger of the two across gravity,
//   less the 95 % radius of those two noises, is the first sample's acceleration: P_err takes
//   the bound scaled to that tilt, (|a_perp| / g)^2 over the bound (at most all of it). At rest,
//   nothing (a bias not yet learnt turns the frame by db t: a ramp, g db T / 2 at the window's
//   end against its radius, 0.1 m/s^2 at 0.04 m/s^2 per sample).
// An acceleration that lasts longer than about 2/3 of rest_filter_tau_s unchanged from the first
// sample is taken as gravity (docs/SELECTIVE_EKF.md).
void SelectiveEkf::settle_start(const ImuInput& in, const Eigen::Vector3d& deviation, double k, double dt_s) {
  SelectiveEkfPreState& pre = x_.pre;
  if (deviation.norm() > p_.rest_accel_max_mps2 || (in.gyro - x_.b_rps).norm() > p_.rest_gyro_max_rps) {
    add_start_bound(1.0);
    return;
  }
  const double t = pre.since_start_s;
  pre.start_dev_0 += deviation * dt_s;
  pre.start_dev_1 += deviation * (t * dt_s);
  pre.start_t_1 += t * dt_s;
  pre.start_t_2 += t * t * dt_s;
  if (t < p_.rest_filter_tau_s) {
    pre.start_lp_weight *= 1.0 - k;  // (a merge above comes before this sample's e <- (1 - k) e)
    return;
  }
  const double g = pre.lp_accel_i.norm();
  const double bound = 0.5 * pre.start_tilt_bound.trace();
  const double det = t * pre.start_t_2 - pre.start_t_1 * pre.start_t_1;  // S0 = t
  if (g > 0.0 && bound > 0.0 && det > 0.0) {
    const Eigen::Vector3d c = (pre.start_t_2 * pre.start_dev_0 - pre.start_t_1 * pre.start_dev_1) / det;
    const Eigen::Vector3d r = (t * pre.start_dev_1 - pre.start_t_1 * pre.start_dev_0) / det;
    const double n2 = p_.accel_noise_density_mps2_per_sqrt_hz * p_.accel_noise_density_mps2_per_sqrt_hz;
    // the line at time s across gravity, less the 95 % radius of its noise and the first sample's
    auto excess = [&](double s) {
      const double across = (c + r * s).cross(pre.lp_accel_i / g).norm();
      const double var = n2 * (1.0 / dt_s + (pre.start_t_2 - 2.0 * s * pre.start_t_1 + s * s * t) / det);
      return std::max(across - std::sqrt(kChi2Dof2P95 * var), 0.0);
    };
    const double tilt = std::max(excess(0.0), excess(t)) / g;
    add_start_bound(std::min(1.0, tilt * tilt / bound));
  } else {
    add_start_bound(1.0);  // no line to settle it by: the bound stands (add_start_bound ends pending)
  }
}

void SelectiveEkf::add_start_bound(double share) {
  SelectiveEkfPreState& pre = x_.pre;
  pre.start_pending = false;
  if (!(share > 0.0)) {
    return;
  }
  // the bound is in the low-pass's frame (the first sample's body frame); the attitude's error is
  // in the body's now (R_ib^T), the low-pass's part e weighted by what it keeps of that sample
  const Eigen::Matrix3d b = share * pre.start_tilt_bound;
  const Eigen::Matrix3d a = pre.q_ib.toRotationMatrix().transpose();
  const double w = pre.start_lp_weight;
  x_.P_err.block<3, 3>(kTh, kTh) += a * b * a.transpose();
  x_.P_err.block<3, 3>(kE, kE) += (w * w) * b;
  x_.P_err.block<3, 3>(kTh, kE) += w * a * b;
  x_.P_err.block<3, 3>(kE, kTh) += w * b * a.transpose();
}

void SelectiveEkf::preprocess(ImuInput& in) {
  // Part of the state (x_.pre), so a replay after a late vision frame re-derives it exactly.
  SelectiveEkfPreState& pre = x_.pre;
  const double dt_s = in.dt_s;
  if (!(dt_s > 0.0)) {
    pre = SelectiveEkfPreState{};
    pre.lp_accel_i = in.accel;
    pre.moving_start = in.gyro.norm() > p_.rest_gyro_max_rps ||
                       std::abs(in.accel.norm() - p_.gravity_mps2) > p_.rest_accel_max_mps2;
    pre.rest_detector.start(in.gyro, in.accel);
    in.up_meas = in.accel.normalized();
    // The low-pass and the attitude both start on this sample's tilt, so the low-pass's error
    // starts as the attitude's tilt error, e = (I - u u^T) dth (its frame is the body's now):
    // the tilt rows see nothing of it until the low-pass forgets the sample. In the estimate's
    // error covariance only; in P (the gains) e starts known, as tuned (a singular P).
    const Eigen::Vector3d u0 = x_.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
    const Eigen::Matrix3d tilt = Eigen::Matrix3d::Identity() - u0 * u0.transpose();
    if (aids::accel_noise_known(p_) && !pre.moving_start) {
      // A start at rest with the accelerometer's noise known: the tilt's error is that sample's
      // noise, not init_sigma_attitude_deg (a bound for a start in motion, whose sample carries
      // external acceleration). Its variance needs the sample's interval, so it is added at the
      // next sample (start_noise_pending); here the tilt directions start known (the heading's
      // start kept) in P_err. The one-sample rest test lets an acceleration across gravity
      // through, up to the tilt bound rest_start_tilt_variance: that is published (or the prior,
      // the smaller) until the samples after it settle it (settle_start).
      const Eigen::Matrix3d prior = tilt * x_.P_err.block<3, 3>(kTh, kTh) * tilt;
      const double bound = rest_start_tilt_variance(p_);
      pre.start_tilt_bound = 0.5 * prior.trace() > bound ? Eigen::Matrix3d(bound * tilt) : prior;
      pre.start_pending = true;
      Mat keep = Mat::Identity();
      keep.block<3, 3>(kTh, kTh) = u0 * u0.transpose();
      x_.P_err = keep * x_.P_err * keep.transpose();
      pre.start_noise_pending = true;
    }
    x_.P_err.middleRows<3>(kE) = tilt * x_.P_err.middleRows<3>(kTh);
    x_.P_err.middleCols<3>(kE) = x_.P_err.middleRows<3>(kE).transpose();
    x_.P_err.block<3, 3>(kE, kE) = tilt * x_.P_err.block<3, 3>(kTh, kTh) * tilt;
    return;
  }
  // Accelerometer low-pass in the frame turned with the state's rate: gravity does not move
  // there, external accelerations average out.
  // (the frame was turned by predict_to with the state's rate)
  pre.since_start_s += dt_s;
  const double k = p_.accel_lowpass_tau_s > 0.0 ? dt_s / (p_.accel_lowpass_tau_s + dt_s) : 1.0;
  // With the accelerometer's noise known, a sample's white noise n (density N, variance N^2 / dt
  // per axis) turns the low-passed vector by u x n / |lp| (u its direction): a rotation of
  // covariance N^2 / (dt |lp|^2) (I - u u^T) in the low-pass's frame
  Eigen::Matrix3d noise_rot = Eigen::Matrix3d::Zero();
  if (aids::accel_noise_known(p_)) {
    const double g2 = pre.lp_accel_i.squaredNorm();
    if (g2 > 0.0) {
      const Eigen::Vector3d ui = pre.lp_accel_i / std::sqrt(g2);
      const double n = p_.accel_noise_density_mps2_per_sqrt_hz;
      noise_rot = (n * n / (dt_s * g2)) * (Eigen::Matrix3d::Identity() - ui * ui.transpose());
    }
    if (pre.start_noise_pending) {
      // the first sample's noise, now that an interval is known (taken as this one): it began
      // both the attitude's tilt and the low-pass (e = dth there, the frames then equal), and one
      // prediction has turned the attitude's part by Exp(w h)^T = R_ib^T
      pre.start_noise_pending = false;
      const Eigen::Matrix3d a = pre.q_ib.toRotationMatrix().transpose();
      x_.P_err.block<3, 3>(kTh, kTh) += a * noise_rot * a.transpose();
      x_.P_err.block<3, 3>(kE, kE) += noise_rot;
      x_.P_err.block<3, 3>(kTh, kE) += a * noise_rot;
      x_.P_err.block<3, 3>(kE, kTh) += noise_rot * a.transpose();
    }
  }
  const Eigen::Vector3d deviation = pre.q_ib * in.accel - pre.lp_accel_i;  // the sample less the low-pass
  if (aids::accel_noise_known(p_)) {
    drive_ext_accel_error(deviation, k, dt_s);
  }
  if (pre.start_pending) {
    settle_start(in, deviation, k, dt_s);
  }
  pre.lp_accel_i += k * deviation;
  // its error: the frame's error less the low-passed past of it, e <- (1 - k) e (rows and
  // columns of P)
  for (Mat* pm : {&x_.P, &x_.P_err}) {
    pm->middleRows<3>(kE) *= 1.0 - k;
    pm->middleCols<3>(kE) *= 1.0 - k;
  }
  // the estimate's error: e <- (1 - k) e + k n, the low-pass's own noise (AR(1))
  x_.P_err.block<3, 3>(kE, kE) += (k * k) * noise_rot;
  Eigen::Vector3d up;
  in.up_meas = safe_normalize(pre.q_ib.conjugate() * pre.lp_accel_i, up) ? up : in.accel.normalized();
  if (p_.tilt_accel_ref_mps2 > 0.0) {
    const double dev = in.accel.norm() - p_.gravity_mps2;
    pre.ext_accel_ms += k * (dev * dev - pre.ext_accel_ms);
    in.tilt_var_scale = 1.0 + pre.ext_accel_ms / (p_.tilt_accel_ref_mps2 * p_.tilt_accel_ref_mps2);
  }
  // Rest detector (gyro and accelerometer against their low-passes).
  if (p_.rest_detection) {
    const RestParams rp{p_.rest_gyro_max_rps, p_.rest_accel_max_mps2, p_.rest_min_s, p_.rest_filter_tau_s};
    pre.rest_detector.step(in.gyro, in.accel, dt_s, rp, x_.b_rps);
  }
  in.rest = pre.rest_detector.rest;
}

// A magnet fixed to the sensor (hard_iron) and a field moved at rest (the core pieces the parallel
// KF uses): judged on the raw reading every sample with a magnetometer, in the accelerometer
// low-pass's frame q_ib (turned with the state's rate: the gyro's rotation between readings, the
// almost inertial frame at rest).
void SelectiveEkf::field_offsets(ImuInput& in) {
  x_.mag_offset_pending = false;
  x_.mag_moved_at_rest = false;
  x_.mag_corrected = false;
  if (!in.has_mag) {
    x_.rest_field.clear();
    return;
  }
  const Eigen::Matrix3d r_ib = x_.pre.q_ib.toRotationMatrix();
  const Eigen::Vector3d raw = in.mag;
  if (p_.hard_iron) {
    const double offset_var = unremoved_offset_var() + removed_offset_var();
    x_.hard_iron.update(in.stamp_ns, r_ib, in.gyro - x_.b_rps, raw, p_.rest_detection && in.rest);
    const HardIronStep step = x_.hard_iron.report().step;
    if (step == HardIronStep::kReset || step == HardIronStep::kStep) {
      // the offset changed (learnt again, or stepped): what the old one put in stays (and is
      // corrected away by the rows);
      // the sensitivities count the new offset's readings from here
      x_.offset_left_var += offset_var;
      x_.heading_per_offset.setZero();
      x_.heading_per_removed_offset.setZero();
    }
    x_.mag_offset_pending = x_.hard_iron.pending();
    if (x_.hard_iron.applied()) {
      in.mag = raw - x_.hard_iron.offset_ut();
      x_.mag_corrected = true;
    }
    // the gate's reference, learnt at start-up on the raw field: was an offset removed now in it?
    // (FieldGate::hard_iron_reading; the up axis is read only while that is still judged)
    const Eigen::Vector3d up = x_.field_gate.startup_reference
                                   ? Eigen::Vector3d(x_.q_world_body.conjugate() * Eigen::Vector3d::UnitZ())
                                   : Eigen::Vector3d::UnitZ();
    x_.field_gate.hard_iron_reading(gp_, x_.hard_iron, in.mag, up, in.dt_s);
  }
  // the raw field: the offset turns with the body, the Earth's field not (at rest neither does)
  const FieldGate& g = x_.field_gate;
  if (!p_.rest_detection || !g.learnt || !(gp_.norm_tol > 0.0) || !(in.dt_s > 0.0)) {
    x_.rest_field.reset();
    return;
  }
  const double tol = gp_.norm_tol * g.m_ut;
  const bool moved = x_.rest_field.step(r_ib * raw, in.rest, in.dt_s, p_.rest_filter_tau_s, gp_.reference_tau_s, tol);
  if (moved) {
    x_.field_gate.offset_after_startup();  // an offset removed from now on came after the start-up
  }
  // held into the motion after it until the hard-iron estimate has judged it (hard_iron) or the
  // field is back within the tolerance of the rest's field before it moved (FieldMovedAtRest::hold)
  x_.mag_moved_at_rest = x_.rest_field.hold(moved, in.rest || !p_.hard_iron, x_.hard_iron.report().judged(), tol);
}

bool SelectiveEkf::update_imu(const ImuSample& s) {
  const SampleCheck c = check_imu_sample(s, last_imu_stamp_ns_, p_.limits, rejections_, p_.use_magnetometer);
  if (anchor_.reanchor(c, s.stamp_ns, p_.limits.max_dt_s)) {
    // Confirmed time jump: keep the state, restart time here; the history cannot span it.
    last_imu_stamp_ns_ = s.stamp_ns;
    x_.stamp_ns = s.stamp_ns - current_delay_ns();
    history_.clear();
    vision_log_.clear();
    return false;
  }
  if (!c.accept) {
    return false;
  }
  ImuInput in;
  // state time: when the measured motion happened
  in.stamp_ns = s.stamp_ns - delay_ns(initialized_ ? c.dt_s : 0.0);
  in.gyro = s.gyro_rps;
  in.accel = s.accel_mps2;
  // switched off (use_magnetometer: false): not even its value goes in, as from a 6-axis sensor
  in.mag = p_.use_magnetometer == MagnetometerUse::kOff ? Eigen::Vector3d::Zero() : s.mag_ut;
  in.has_mag = c.mag_ok;
  const bool split = p_.imu_measurement == ImuMeasurement::kSplit;
  if (c.mag_ok) {
    learn_reference(s);
    if (!split && gn_.update(s)) {
      in.has_q_imu = true;
      in.q_imu = gn_.result().q_world_body;
    }
  }
  in.dt_s = initialized_ ? c.dt_s : 0.0;
  last_imu_stamp_ns_ = s.stamp_ns;
  if (!initialized_) {
    // Tilt from the accelerometer; heading from Gauss-Newton or (kSplit) the magnetometer, and
    // without one (6-axis) ZYX yaw 0, as in every filter (quat_tilt_yaw0).
    x_.q_world_body = in.has_q_imu ? in.q_imu : quat_tilt_yaw0(in.accel);
    if (!in.has_q_imu && in.has_mag) {
      const Eigen::Vector3d mw = x_.q_world_body * in.mag;
      if (std::hypot(mw.x(), mw.y()) > 1e-3 * in.mag.norm()) {
        const double dpsi = 0.5 * kPi - std::atan2(mw.y(), mw.x());
        x_.q_world_body =
            (Eigen::Quaterniond(Eigen::AngleAxisd(dpsi, Eigen::Vector3d::UnitZ())) * x_.q_world_body)
                .normalized();
      }
    }
    x_.w_rps = in.gyro;
    x_.stamp_ns = in.stamp_ns;
    preprocess(in);  // starts the low-pass and rest detector
    initialized_ = true;
    history_.push_back({in, x_});
    time_offset_.add_gyro(in.stamp_ns, in.gyro - x_.b_rps, x_.P_err.block<3, 3>(kB, kB));
    return true;
  }
  // Queued (future-stamped) vision strictly before this sample goes first, in stamp order. After a
  // re-anchored time jump the history is empty: the state's own time is the previous sample's.
  const int64_t previous_ns = history_.empty() ? x_.stamp_ns : history_.back().input.stamp_ns;
  auto it = std::upper_bound(vision_log_.begin(), vision_log_.end(), previous_ns,
                             [](int64_t t, const VisionPose& v) { return t < v.capture_stamp_ns; });
  for (; it != vision_log_.end() && it->capture_stamp_ns < in.stamp_ns; ++it) {
    predict_to(it->capture_stamp_ns);
    process_vision(*it, true);
  }
  predict_to(in.stamp_ns);
  process_imu(in, true);
  history_.push_back({in, x_});
  time_offset_.add_gyro(in.stamp_ns, in.gyro - x_.b_rps, x_.P_err.block<3, 3>(kB, kB));
  for (; it != vision_log_.end() && it->capture_stamp_ns == in.stamp_ns; ++it) {
    process_vision(*it, true);
  }
  blend_output(s.gyro_rps, c.dt_s);
  // Trim the history to history_s (keep at least the newest entry) and the vision log with it.
  const int64_t oldest = in.stamp_ns - seconds_to_ns(p_.history_s);
  while (history_.size() > 1 && history_.front().input.stamp_ns < oldest) {
    history_.pop_front();
  }
  while (!vision_log_.empty() &&
         vision_log_.front().capture_stamp_ns < history_.front().input.stamp_ns) {
    vision_log_.pop_front();
  }
  if (!healthy()) {
    reset_unhealthy(s.stamp_ns);
    return false;
  }
  return true;
}

void SelectiveEkf::blend_output(const Eigen::Vector3d& gyro_rps, double dt_s) {
  // The output turns with the measured rate (gyro - bias) and follows the state's estimate with
  // corrections limited to output_max_correction_dps: a large correction (vision back after a
  // blackout) becomes a glide instead of a jump. Not part of the filter state (replays do not
  // touch it).
  if (!(p_.output_max_correction_dps > 0.0)) {
    return;
  }
  const Eigen::Quaterniond target = state_output();
  if (!out_ready_ || !(dt_s > 0.0)) {
    out_q_ = target;
    out_ready_ = true;
    return;
  }
  const Eigen::Quaterniond pred = (out_q_ * quat_exp((gyro_rps - x_.b_rps) * dt_s)).normalized();
  const Eigen::Quaterniond d = pred.conjugate() * quat_align_sign(target, pred);
  // |d.vec| = sin(angle / 2): the common case (a correction within the limit) takes the target
  // without a log/exp; a reset (above 30 deg) is taken at once as well.
  const double half_sin = d.vec().norm();
  const double max_step = p_.output_max_correction_dps * kRadPerDeg * dt_s;
  if (half_sin <= 0.5 * max_step || half_sin > kOutputSnapHalfSin) {
    out_q_ = target;
    return;
  }
  // Larger corrections are spread at output_max_correction_dps.
  const Eigen::Vector3d e = quat_log(d);
  const double k = max_step / e.norm();
  out_q_ = quat_canonical((pred * quat_exp(e * k)).normalized());
}

bool SelectiveEkf::update_vision(const VisionPose& v_in) {
  ++vc_.received;
  SourceStatus& sa = status_of(SelectiveEkfAid::kVisionAttitude);
  if (!aids::finite_quat(v_in.q_world_camera) || v_in.capture_stamp_ns < 0 ||
      (v_in.has_position && !v_in.p_world_camera_m.allFinite()) ||
      (std::isfinite(v_in.sigma_rad) && v_in.sigma_rad <= 0.0) ||
      (std::isfinite(v_in.sigma_m) && v_in.sigma_m <= 0.0) ||
      (aids::has_attitude_covariance(v_in) && !aids::attitude_covariance_ok(v_in.attitude_covariance_world))) {
    ++vc_.bad_input;
    aids::record(sa, Decision::kRejectedBadInput, v_in.capture_stamp_ns, true);
    return false;
  }
  if (!initialized_ || history_.empty()) {
    ++vc_.before_init;
    aids::record(sa, Decision::kRejectedBadInput, v_in.capture_stamp_ns, true);
    return false;
  }
  if (v_in.capture_stamp_ns < history_.front().input.stamp_ns) {
    ++vc_.too_old;
    aids::record(sa, Decision::kRejectedTooOld, v_in.capture_stamp_ns, true);
    return false;
  }
  VisionPose v = v_in;
  v.q_world_camera.normalize();
  aids::apply_time_offset(time_offset_, p_, x_.w_rps, v);  // onto the IMU clock
  if (v.capture_stamp_ns < history_.front().input.stamp_ns) {
    ++vc_.too_old;
    aids::record(sa, Decision::kRejectedTooOld, v.capture_stamp_ns, true);
    return false;
  }
  if (v.capture_stamp_ns < newest_vision_capture_ns_) {
    ++vc_.out_of_order;
  }
  newest_vision_capture_ns_ = std::max(newest_vision_capture_ns_, v.capture_stamp_ns);
  // Insert after measurements with the same or earlier capture stamp.
  auto pos = std::upper_bound(vision_log_.begin(), vision_log_.end(), v.capture_stamp_ns,
                              [](int64_t t, const VisionPose& e) { return t < e.capture_stamp_ns; });
  const auto fresh = static_cast<size_t>(pos - vision_log_.begin());
  vision_log_.insert(pos, v);
  const int64_t state_now_ns = last_imu_stamp_ns_ - current_delay_ns();
  if (v.capture_stamp_ns > state_now_ns) {
    ++vc_.future;  // applied when the IMU reaches its capture stamp
    return true;
  }
  ++vc_.applied;
  // Snapshot at or before the capture stamp (largest stamp <= capture).
  auto snap = std::upper_bound(history_.begin(), history_.end(), v.capture_stamp_ns,
                               [](int64_t t, const HistoryEntry& e) { return t < e.input.stamp_ns; });
  const auto j = static_cast<size_t>(snap - history_.begin()) - 1;
  x_ = history_[j].post;
  const int64_t t_j = history_[j].input.stamp_ns;
  auto vi = static_cast<size_t>(
      std::lower_bound(vision_log_.begin(), vision_log_.end(), t_j,
                       [](const VisionPose& e, int64_t t) { return e.capture_stamp_ns < t; }) -
      vision_log_.begin());
  for (size_t i = j + 1; i < history_.size(); ++i) {
    const int64_t t_i = history_[i].input.stamp_ns;
    for (; vi < vision_log_.size() && vision_log_[vi].capture_stamp_ns < t_i; ++vi) {
      predict_to(vision_log_[vi].capture_stamp_ns);
      process_vision(vision_log_[vi], vi == fresh);
    }
    predict_to(t_i);
    process_imu(history_[i].input, false);
    history_[i].post = x_;
    ++vc_.replayed_imu_samples;
  }
  for (; vi < vision_log_.size() && vision_log_[vi].capture_stamp_ns <= state_now_ns; ++vi) {
    predict_to(vision_log_[vi].capture_stamp_ns);
    process_vision(vision_log_[vi], vi == fresh);
  }
  if (!healthy()) {
    reset_unhealthy(v.capture_stamp_ns);
    return false;
  }
  return true;
}

bool SelectiveEkf::healthy() {
  const bool full = health_.full_due();
  // P_err finite: x - x is 0 for a finite x and NaN for an infinite or NaN one, so the sum is NaN
  // exactly when allFinite() is false (a vectorised sum instead of a test per coefficient)
  return all_finite(x_.w_rps, x_.q_world_body.coeffs(), x_.b_rps, x_.t_m, x_.v_mps, out_q_.coeffs()) &&
         covariance_ok(x_.P, full) && !std::isnan((x_.P_err - x_.P_err).sum());
}

void SelectiveEkf::reset_unhealthy(int64_t stamp_ns) {
  const RejectCounters rejections = rejections_;
  const auto status = status_;
  const VisionCounters vc = vc_;
  const uint64_t untrusted = mag_.untrusted_samples;
  StateHealth health = health_;
  reset();
  rejections_ = rejections;
  status_ = status;
  vc_ = vc;
  mag_.untrusted_samples = untrusted;
  ++health.resets;
  health_ = health;
  for (SourceStatus& st : status_) {
    if (st.last != Decision::kNone) {
      aids::record(st, Decision::kRejectedStateReset, stamp_ns, true);
    }
  }
}

std::map<std::string, uint64_t> SelectiveEkfFilter::rejections() const {
  std::map<std::string, uint64_t> m = ekf_.imu_rejections().to_map();
  const VisionCounters& vc = ekf_.vision_counters();
  auto put = [&m](const std::string& k, uint64_t n) {
    if (n != 0) {
      m[k] = n;
    }
  };
  put("vision_too_old", vc.too_old);
  put("vision_bad_input", vc.bad_input);
  put("vision_before_init", vc.before_init);
  put("state_reset", ekf_.state_resets());
  for (size_t s = 0; s < static_cast<size_t>(SelectiveEkfAid::kCount); ++s) {
    const auto aid = static_cast<SelectiveEkfAid>(s);
    const SourceStatus& st = ekf_.status(aid);
    for (size_t d = 0; d < st.by_decision.size(); ++d) {
      const auto dec = static_cast<Decision>(d);
      if (dec != Decision::kFused && dec != Decision::kFusedInflated && dec != Decision::kNone &&
          dec != Decision::kReset) {
        put(std::string(to_string(source_of(aid))) + "_" + to_string(dec),
            st.by_decision[d]);
      }
    }
  }
  return m;
}

}  // namespace poise
