#include "poise/selective_ekf/selective_ekf.h"

#include "poise/core/params_check.h"

#include <algorithm>
#include <stdexcept>

namespace poise {
namespace {

constexpr double kNsToS = 1e-9;
/// Output limit: a state-output difference above 30 deg is a reset, taken at once (sin(15 deg)).
constexpr double kOutputSnapHalfSin = 0.25881904510252074;
/// Gate used only to report a test ratio for sources that are never gated (gyro, q_imu), sigma.
constexpr double kReportGateSigma = 5.0;

int64_t seconds_to_ns(double s) { return static_cast<int64_t>(std::llround(s * 1e9)); }

bool finite_quat(const Eigen::Quaterniond& q) {
  return q.coeffs().allFinite() && q.coeffs().norm() > 0.5 && q.coeffs().norm() < 1.5;
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

void validate(const SelectiveEkfParams& p) {
  const ParamCheck check("selective_ekf");
  check.positive(p.sigma_angular_accel, "sigma_angular_accel", "rad/s^2/sqrt(Hz)");
  check.positive(p.sigma_linear_accel, "sigma_linear_accel", "m/s^2/sqrt(Hz)");
  check.non_negative(p.sigma_attitude_walk, "sigma_attitude_walk", "rad/sqrt(s)");
  check.positive(p.sigma_gyro_rps, "sigma_gyro_rps", "rad/s");
  check.non_negative(p.sigma_bias_walk, "sigma_bias_walk", "rad/s/sqrt(s)");
  check.non_negative(p.accel_lowpass_tau_s, "accel_lowpass_tau_s", "s, 0 = raw accelerometer");
  check.require(std::isnan(p.sigma_tilt_rad_sqrt_s) || p.sigma_tilt_rad_sqrt_s > 0.0, "sigma_tilt_rad_sqrt_s",
                "> 0 (rad sqrt(s)) or null (derived from accel_lowpass_tau_s)");
  check.require(!std::isnan(p.sigma_tilt_rad_sqrt_s) || p.accel_lowpass_tau_s > 0.0, "accel_lowpass_tau_s",
                "> 0 (s) while sigma_tilt_rad_sqrt_s is null (it sets the tilt time constant)");
  check.non_negative(p.tilt_accel_ref_mps2, "tilt_accel_ref_mps2", "m/s^2, 0 = off");
  check.require(p.gravity_mps2 > 5.0 && p.gravity_mps2 < 15.0, "gravity_mps2", "in (5, 15) (m/s^2)");
  check.non_negative(p.output_max_correction_dps, "output_max_correction_dps", "deg/s, 0 = off");
  check.require(p.aiding_period_s >= 0.0 && p.aiding_period_s <= 1.0, "aiding_period_s", "in [0, 1] (s)");
  check.positive(p.sigma_heading_rad_sqrt_s, "sigma_heading_rad_sqrt_s", "rad sqrt(s)");
  check.require(p.heading_disturbance_weight >= 0.0 && p.heading_disturbance_weight <= 1.0e6, "heading_disturbance_weight",
                "in [0, 1e6] (0 = off; larger would make the heading variance overflow)");
  check.positive(p.rest_gyro_max_rps, "rest_gyro_max_rps", "rad/s");
  check.positive(p.rest_accel_max_mps2, "rest_accel_max_mps2", "m/s^2");
  check.non_negative(p.rest_min_s, "rest_min_s", "s");
  check.positive(p.rest_filter_tau_s, "rest_filter_tau_s", "s");
  check.positive(p.sigma_rest_rate_rps, "sigma_rest_rate_rps", "rad/s");
  check.positive(p.init_sigma_bias_rps, "init_sigma_bias_rps", "rad/s");
  check.positive(p.sigma_imu_quat_deg, "sigma_imu_quat_deg", "deg");
  check.positive(p.sigma_vision_deg, "sigma_vision_deg", "deg");
  check.positive(p.sigma_vision_m, "sigma_vision_m", "m");
  check.require(p.startup_samples >= 1, "startup_samples", ">= 1 (samples)");
  check.positive(p.disturbance_angle_threshold_deg, "disturbance_angle_threshold_deg", "deg");
  check.positive(p.mag_norm_threshold, "mag_norm_threshold", "relative");
  heading_field_gate(p).validate(check, {"field_magnitude_ut", "dip_deg", "field_startup_s", "heading_norm_tolerance",
                                          "heading_dip_tolerance_deg", "field_reference_tau_s", "field_reacquire_s",
                                          "field_reacquire_tol", "field_max_reject_s"});
  check.require(p.quat_error_threshold_deg > 0.0 && p.quat_error_threshold_deg <= 180.0,
                "quat_error_threshold_deg", "in (0, 180] (deg)");
  check.require(std::isfinite(p.inflate_factor) && p.inflate_factor >= 1.0, "inflate_factor", "finite and >= 1");
  check.non_negative(p.untrusted_hold_s, "untrusted_hold_s", "s");
  check.positive(p.q_error_lockout_s, "q_error_lockout_s", "s");
  check.positive(p.vision_anchor_s, "vision_anchor_s", "s");
  check.positive(p.vision_gate_sigma, "vision_gate_sigma", "standard deviations");
  check.require(p.vision_reset_after_rejections >= 1, "vision_reset_after_rejections", ">= 1 (samples)");
  check.require(p.history_s > 0.0 && p.history_s <= 5.0, "history_s", "in (0, 5] (s)");
  check.require(std::abs(p.vision_time_offset_s) <= 0.2, "vision_time_offset_s", "in [-0.2, 0.2] (s)");
  check.require(p.imu_delay_s >= 0.0 && p.imu_delay_s <= 0.05, "imu_delay_s", "in [0, 0.05] (s)");
  check.require(finite_quat(p.q_body_camera), "q_body_camera", "a finite unit quaternion [w, x, y, z]");
  check.require(p.p_body_camera_m.allFinite(), "p_body_camera_m", "finite (m)");
  check.positive(p.init_sigma_attitude_deg, "init_sigma_attitude_deg", "deg");
  check.positive(p.init_sigma_rate_rps, "init_sigma_rate_rps", "rad/s");
  check.positive(p.init_sigma_position_m, "init_sigma_position_m", "m");
  check.positive(p.init_sigma_velocity_mps, "init_sigma_velocity_mps", "m/s");
  validate(p.limits, check);
  p.gauss_newton.validate("selective_ekf.gauss_newton");
}

FieldGateParams heading_field_gate(const SelectiveEkfParams& p) {
  FieldGateParams g;
  g.enabled = p.gating_enabled;
  g.field_magnitude_ut = p.field_magnitude_ut;
  g.dip_deg = p.dip_deg;
  g.startup_s = p.field_startup_s;
  g.norm_tol = p.heading_norm_tolerance;
  g.dip_tol_deg = p.heading_dip_tolerance_deg;
  g.reference_tau_s = p.field_reference_tau_s;
  g.reacquire_s = p.field_reacquire_s;
  g.reacquire_tol = p.field_reacquire_tol;
  g.max_reject_s = p.field_max_reject_s;
  return g;
}

SelectiveEkf::SelectiveEkf(const SelectiveEkfParams& params) : p_(params) {
  validate(p_);
  gp_ = heading_field_gate(p_);
  p_.q_body_camera.normalize();
  imu_delay_ns_ = seconds_to_ns(p_.imu_delay_s);
  // The dip reference and input limits are shared with the Gauss-Newton source.
  if (std::isfinite(p_.dip_deg) && !std::isfinite(p_.gauss_newton.dip_deg)) {
    p_.gauss_newton.dip_deg = p_.dip_deg;
  }
  p_.gauss_newton.limits = p_.limits;
  gn_ = GaussNewton(p_.gauss_newton);
  reset();
}

void SelectiveEkf::reset() {
  gn_.reset();
  x_ = SelectiveEkfState{};
  x_.field_gate.reset(gp_);
  x_.P.setZero();
  const double sa = p_.init_sigma_attitude_deg * kRadPerDeg;
  x_.P.diagonal().segment<3>(kW).setConstant(p_.init_sigma_rate_rps * p_.init_sigma_rate_rps);
  x_.P.diagonal().segment<3>(kTh).setConstant(sa * sa);
  x_.P.diagonal().segment<3>(kB).setConstant(p_.init_sigma_bias_rps * p_.init_sigma_bias_rps);
  x_.P.diagonal().segment<3>(kT).setConstant(p_.init_sigma_position_m * p_.init_sigma_position_m);
  x_.P.diagonal().segment<3>(kV).setConstant(p_.init_sigma_velocity_mps *
                                              p_.init_sigma_velocity_mps);
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
}

Eigen::Quaterniond SelectiveEkf::q_world_body() const {
  return p_.output_max_correction_dps > 0.0 && out_ready_ ? out_q_ : state_output();
}

Eigen::Quaterniond SelectiveEkf::state_output() const {
  if (imu_delay_ns_ == 0) {
    return quat_canonical(x_.q_world_body);
  }
  const double d = static_cast<double>(imu_delay_ns_) * kNsToS;
  return quat_canonical((x_.q_world_body * quat_exp(x_.w_rps * d)).normalized());
}

Eigen::Vector3d SelectiveEkf::position_m() const {
  return x_.t_m + x_.v_mps * (static_cast<double>(imu_delay_ns_) * kNsToS);
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
  if (x_.coupled) {
    auto apply_f = [&](const Mat& m) {
      Mat out = m;
      out.middleRows<3>(kTh) = a * m.middleRows<3>(kTh) + b * m.middleRows<3>(kW);
      out.middleRows<3>(kT) += h * m.middleRows<3>(kV);
      return out;
    };
    const Mat fp = apply_f(x_.P);
    const Mat fpf = apply_f(fp.transpose());
    x_.P = 0.5 * (fpf + fpf.transpose());
  } else {
    using Mat6 = Eigen::Matrix<double, 6, 6>;
    using MatA = Eigen::Matrix<double, kAttN, kAttN>;
    const MatA att = x_.P.topLeftCorner<kAttN, kAttN>();  // [w, th, b]: th' = a th + b w
    auto apply_att = [&](const MatA& m) {
      MatA out = m;
      out.middleRows<3>(kTh) = a * m.middleRows<3>(kTh) + b * m.middleRows<3>(kW);
      return out;
    };
    const MatA fa = apply_att(att);
    const MatA fpf = apply_att(fa.transpose());
    x_.P.topLeftCorner<kAttN, kAttN>() = 0.5 * (fpf + fpf.transpose());  // exactly symmetric
    Mat6 tr = x_.P.bottomRightCorner<6, 6>();  // [t, v]: t' = t + h v
    tr.topRows<3>() += h * tr.bottomRows<3>();
    tr.leftCols<3>() += h * tr.rightCols<3>();
    x_.P.bottomRightCorner<6, 6>() = tr;
  }
  const double qw = p_.sigma_angular_accel * p_.sigma_angular_accel * h;
  const double qth = p_.sigma_attitude_walk * p_.sigma_attitude_walk * h;
  const double qv = p_.sigma_linear_accel * p_.sigma_linear_accel * h;
  const double qb = p_.sigma_bias_walk * p_.sigma_bias_walk * h;
  // Q of the continuous white-noise models over h: [q h, q h^2/2; q h^2/2, q h^3/3] for each
  // (rate, attitude) and (velocity, position) pair. The cross terms let the gyro row correct the
  // attitude integrated with the previous rate (trapezoid-like, no one-sample lag).
  const double qc_w = qw * h / 2.0;
  const double qc_v = qv * h / 2.0;
  for (int i = 0; i < 3; ++i) {
    x_.P(kW + i, kW + i) += qw;
    x_.P(kTh + i, kTh + i) += qth + qw * h * h / 3.0;
    x_.P(kW + i, kTh + i) += qc_w;
    x_.P(kTh + i, kW + i) += qc_w;
    x_.P(kB + i, kB + i) += qb;
    x_.P(kV + i, kV + i) += qv;
    x_.P(kT + i, kT + i) += qv * h * h / 3.0;
    x_.P(kV + i, kT + i) += qc_v;
    x_.P(kT + i, kV + i) += qc_v;
  }
  x_.stamp_ns = stamp_ns;
}

// ------------------------------------------------------------------------------------ update
namespace {

/// Update with M rows of a dense H (M x N) and diagonal R, processed one row at a time (exact for
/// a diagonal R: the same result as the batch update, at O(M N^2) instead of O(M N^3)):
///   v_i = P h_i^T (prior), u_i = v_i - sum_{j<i} u_j (h_i . u_j) / s_j (= P_{i-1} h_i^T),
///   s_i = h_i . u_i + r_i, dx += u_i (y_i - h_i . dx) / s_i, P -= u_i u_i^T / s_i.
/// P - K S K^T equals the Joseph form for this (optimal) gain; each rank-one term is symmetric.
/// The status gets the innovation, the prior innovation variance diag(H P H^T + R) and the test
/// ratio; the gate tests the prior variance. Leaves `p` and `dx` untouched when the gate rejects
/// or `report_only`. Returns whether the rows were applied.
template <int N, int M, typename PMat>
bool sequential_update(PMat&& p, const Eigen::Matrix<double, M, N>& h,
                       const Eigen::Matrix<double, M, 1>& innov,
                       const Eigen::Matrix<double, M, 1>& r_diag, double gate_sigma, bool gate,
                       bool report_only, SourceStatus& st, Eigen::Matrix<double, N, 1>& dx) {
  Eigen::Matrix<double, N, M> u = p.lazyProduct(h.transpose());  // prior P H^T
  double ratio = 0.0;
  st.innovation.setZero();
  st.innovation_variance.setZero();
  for (int i = 0; i < M; ++i) {
    const double s_prior = h.row(i).dot(u.col(i)) + r_diag[i];
    st.innovation[i] = innov[i];
    st.innovation_variance[i] = s_prior;
    ratio = std::max(ratio, innov[i] * innov[i] / (gate_sigma * gate_sigma * s_prior));
  }
  st.test_ratio = ratio;
  if (report_only || (gate && !(ratio <= 1.0))) {
    return false;
  }
  dx.setZero();
  Eigen::Matrix<double, M, 1> s;
  for (int i = 0; i < M; ++i) {
    for (int j = 0; j < i; ++j) {
      u.col(i) -= u.col(j) * (h.row(i).dot(u.col(j)) / s[j]);
    }
    s[i] = h.row(i).dot(u.col(i)) + r_diag[i];
    dx += u.col(i) * ((innov[i] - h.row(i).dot(dx)) / s[i]);  // (5), (6)
  }
  for (int i = 0; i < M; ++i) {
    const Eigen::Matrix<double, N, 1> w = u.col(i) / std::sqrt(s[i]);
    p.noalias() -= w * w.transpose();  // (7), exactly symmetric
  }
  return true;
}

/// sequential_update on the diagonal block [Off, Off + NB) of P alone (the caller knows that H
/// and P's cross terms outside it are zero); dx gets the block's correction.
template <int Off, int NB, int N, int M>
bool update_block(Eigen::Matrix<double, N, N>& p, const Eigen::Matrix<double, M, N>& h,
                  const Eigen::Matrix<double, M, 1>& innov, const Eigen::Matrix<double, M, 1>& r_diag,
                  double gate_sigma, bool gate, bool report_only, SourceStatus& st,
                  Eigen::Matrix<double, N, 1>& dx) {
  Eigen::Matrix<double, NB, 1> d;
  const Eigen::Matrix<double, M, NB> hb = h.template middleCols<NB>(Off);
  const bool ok = sequential_update<NB, M>(p.template block<NB, NB>(Off, Off), hb, innov, r_diag,
                                           gate_sigma, gate, report_only, st, d);
  if (ok) {
    dx.template segment<NB>(Off) = d;
  }
  return ok;
}

}  // namespace

template <int M>
bool SelectiveEkf::fuse(const Eigen::Matrix<double, M, kN>& h, const Eigen::Matrix<double, M, 1>& innov,
                        const Eigen::Matrix<double, M, 1>& r_diag, double gate_sigma, bool gate,
                        SourceStatus& st, bool report_only) {
  const bool att = (h.template leftCols<kAttN>().array() != 0.0).any();
  const bool trans = (h.template rightCols<kN - kAttN>().array() != 0.0).any();
  Vec dx = Vec::Zero();
  bool ok = false;
  if (!x_.coupled && !(att && trans)) {
    // No cross-covariance between [w, th, b] and [t, v]: rows touching one block update it alone
    // (the rest of K is exactly zero), with the same result as the full covariance.
    ok = att ? update_block<0, kAttN>(x_.P, h, innov, r_diag, gate_sigma, gate, report_only, st, dx)
             : update_block<kAttN, kN - kAttN>(x_.P, h, innov, r_diag, gate_sigma, gate, report_only,
                                               st, dx);
  } else {
    x_.coupled = x_.coupled || !report_only;  // a lever-arm fix correlates attitude and position
    ok = sequential_update<kN, M>(x_.P, h, innov, r_diag, gate_sigma, gate, report_only, st, dx);
  }
  if (ok) {
    inject(dx);
  }
  return ok;
}

void SelectiveEkf::inject(const Vec& dx) {
  x_.w_rps += dx.segment<3>(kW);
  x_.q_world_body = (x_.q_world_body * quat_exp(dx.segment<3>(kTh))).normalized();
  x_.b_rps += dx.segment<3>(kB);
  x_.t_m += dx.segment<3>(kT);
  x_.v_mps += dx.segment<3>(kV);
}

void SelectiveEkf::record(SourceStatus& st, Decision d, int64_t stamp_ns, bool first_pass) const {
  st.last = d;
  st.last_stamp_ns = stamp_ns;
  const bool fused = d == Decision::kFused || d == Decision::kFusedInflated || d == Decision::kReset;
  if (fused) {
    st.last_fused_stamp_ns = stamp_ns;
  }
  if (first_pass) {
    ++st.by_decision[static_cast<size_t>(d)];
    if (fused) {
      ++st.fused;
    } else {
      ++st.rejected;
    }
  }
}

void SelectiveEkf::process_imu(const ImuInput& in_raw, bool first_pass) {
  ImuInput in = in_raw;
  preprocess(in);
  const int64_t now = in.stamp_ns;
  // Gyro rows: y = w + b.
  {
    Eigen::Matrix<double, 3, kN> h = Eigen::Matrix<double, 3, kN>::Zero();
    h.middleCols<3>(kW).setIdentity();
    h.middleCols<3>(kB).setIdentity();
    const double r = p_.sigma_gyro_rps * p_.sigma_gyro_rps;
    SourceStatus& sg = status_[static_cast<size_t>(SelectiveEkfAid::kGyro)];
    fuse<3>(h, in.gyro - x_.w_rps - x_.b_rps, Eigen::Vector3d::Constant(r), kReportGateSigma, false, sg);
    record(sg, Decision::kFused, now, first_pass);
  }
  // Zero-rate rows at rest: y = 0 = w (with the gyro row, observes b).
  if (in.rest) {
    Eigen::Matrix<double, 3, kN> h = Eigen::Matrix<double, 3, kN>::Zero();
    h.middleCols<3>(kW).setIdentity();
    const double r = p_.sigma_rest_rate_rps * p_.sigma_rest_rate_rps;
    SourceStatus& sz = status_[static_cast<size_t>(SelectiveEkfAid::kZeroRate)];
    fuse<3>(h, -x_.w_rps, Eigen::Vector3d::Constant(r), kReportGateSigma, false, sz);
    record(sz, Decision::kFused, now, first_pass);
  }
  // The predicted up axis is only as good as the tilt: in the paper's quaternion mode without a
  // recent vision fix the tilt is carried by the gyro alone (q_imu gated), and a drifting tilt
  // would keep the test failing (self-locking), so the raw accelerometer is used there.
  const bool anchored = x_.last_vision_fused_ns >= 0 &&
                        now - x_.last_vision_fused_ns <= seconds_to_ns(p_.vision_anchor_s);
  if (p_.imu_measurement == ImuMeasurement::kQuaternion) {
    process_imu_quat(in, first_pass, anchored);
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
    process_tilt(in, first_pass);
    process_heading(in, first_pass, anchored);
  }
}

bool SelectiveEkf::mag_trusted(const ImuInput& in, const Eigen::Vector3d& up, double theta_q,
                               bool anchored, bool first_pass) {
  const int64_t now = in.stamp_ns;
  const double theta_m = angle_between_vectors(in.mag, up);  // (8)
  mag_.disturbance_angle_deg = theta_m * kDegPerRad;
  mag_.quat_error_deg = theta_q * kDegPerRad;
  // kSplit measures the dip against the filtered tilt (accurate without vision) and |m| with the
  // parallel KF's field gate (learnt, following, re-acquired reference); its quaternion-error test
  // compares with a heading that only vision anchors (see the notation).
  const bool split = p_.imu_measurement == ImuMeasurement::kSplit;
  bool field_disturbed = false;
  if (split) {
    FieldGate& g = x_.field_gate;
    const FieldVerdict v = g.step(gp_, in.mag, up, in.dt_s);
    g.tick(gp_, in.dt_s);
    field_disturbed = v == FieldVerdict::kGated;
    mag_.reference_ready = g.learnt;
    mag_.dip_deg = g.dip_rad * kDegPerRad;
    mag_.reference_angle_deg = 90.0 + mag_.dip_deg;
    mag_.norm_ratio = g.m_ut > 0.0 ? in.mag.norm() / g.m_ut : 1.0;
    mag_.norm_test_failed = field_disturbed && std::abs(g.norm_ratio(gp_)) > 1.0;
    mag_.angle_test_failed = field_disturbed && (g.last_sin_dip < g.sin_lo || g.last_sin_dip > g.sin_hi);
  } else {
    mag_.angle_test_failed = mag_.reference_ready &&
                             std::abs(theta_m - ref_angle_rad_) > p_.disturbance_angle_threshold_deg * kRadPerDeg;
    mag_.norm_test_failed = false;
    if (p_.mag_norm_test && ref_norm_ut_ > 0.0) {
      mag_.norm_ratio = in.mag.norm() / ref_norm_ut_;
      mag_.norm_test_failed = std::abs(mag_.norm_ratio - 1.0) > p_.mag_norm_threshold;
    }
    field_disturbed = mag_.angle_test_failed || mag_.norm_test_failed;
  }
  bool q_fail = p_.quat_error_test && (!split || anchored) &&
                theta_q > p_.quat_error_threshold_deg * kRadPerDeg;
  if (q_fail) {
    if (x_.q_error_fail_since_ns < 0) {
      x_.q_error_fail_since_ns = now;
    }
    if (!anchored && now - x_.q_error_fail_since_ns > seconds_to_ns(p_.q_error_lockout_s)) {
      q_fail = false;  // lock-out release: the prediction, not the measurement, may have drifted
    }
  } else {
    x_.q_error_fail_since_ns = -1;
  }
  mag_.quat_error_test_failed = q_fail;
  const bool disturbed = field_disturbed || q_fail;
  if (p_.gating_enabled && disturbed) {
    x_.untrusted_until_ns = now + seconds_to_ns(p_.untrusted_hold_s);
  }
  // untrusted while a test fails, and for untrusted_hold_s after the last failure
  const bool trusted = !p_.gating_enabled ||
                       (!disturbed && (x_.untrusted_until_ns < 0 || now >= x_.untrusted_until_ns));
  mag_.trusted = trusted;
  if (!trusted && first_pass) {
    ++mag_.untrusted_samples;
  }
  return trusted;
}

void SelectiveEkf::process_imu_quat(const ImuInput& in, bool first_pass, bool anchored) {
  const int64_t now = in.stamp_ns;
  SourceStatus& sq = status_[static_cast<size_t>(SelectiveEkfAid::kImuQuat)];
  if (!in.has_q_imu) {
    record(sq, Decision::kRejectedNoMag, now, first_pass);
    return;
  }
  // Disturbance angle (8) and quaternion error (9)-(10).
  Eigen::Vector3d up = in.accel;
  if (p_.up_source == UpSource::kFiltered && anchored) {
    up = x_.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
  }
  const double theta_q = quat_angle_between(x_.q_world_body, in.q_imu);  // (9)-(10)
  const bool trusted = mag_trusted(in, up, theta_q, anchored, first_pass);
  const bool q_fail = mag_.quat_error_test_failed;
  const Decision reject_reason = (mag_.angle_test_failed || mag_.norm_test_failed || !q_fail)
                                     ? Decision::kRejectedDisturbance
                                     : Decision::kRejectedQuatError;

  const Eigen::Quaterniond qm = quat_align_sign(in.q_imu, x_.q_world_body);
  const Eigen::Vector3d innov = quat_log(x_.q_world_body.conjugate() * qm);
  const double sig = p_.sigma_imu_quat_deg * kRadPerDeg;
  double r = sig * sig;
  Eigen::Matrix<double, 3, kN> h = Eigen::Matrix<double, 3, kN>::Zero();
  h.middleCols<3>(kTh).setIdentity();
  if (!trusted && p_.action == ImuQuatAction::kDrop) {
    // Report the innovation the rows would have had, then leave them out.
    fuse<3>(h, innov, Eigen::Vector3d::Constant(r), kReportGateSigma, false, sq, true);
    record(sq, reject_reason, now, first_pass);
    return;
  }
  if (!trusted) {
    r *= p_.inflate_factor;
  }
  fuse<3>(h, innov, Eigen::Vector3d::Constant(r), kReportGateSigma, false, sq);
  record(sq, trusted ? Decision::kFused : Decision::kFusedInflated, now, first_pass);
}

void SelectiveEkf::process_tilt(const ImuInput& in, bool first_pass) {
  SourceStatus& st = status_[static_cast<size_t>(SelectiveEkfAid::kAccelTilt)];
  if (!(in.dt_s > 0.0)) {
    return;
  }
  const Eigen::Vector3d u = x_.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();  // R^T e_z
  // e1, e2: orthonormal, perpendicular to u. z_up x u = dth_perp (small angles), so the rows are
  // e_i . (z_up x u) = e_i . dth.
  const Eigen::Vector3d a = std::abs(u.x()) < 0.6 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d e1 = u.cross(a).normalized();
  const Eigen::Vector3d e2 = u.cross(e1);
  const Eigen::Vector3d c = in.up_meas.cross(u);
  Eigen::Matrix<double, 2, kN> h = Eigen::Matrix<double, 2, kN>::Zero();
  h.block<1, 3>(0, kTh) = e1.transpose();
  h.block<1, 3>(1, kTh) = e2.transpose();
  const Eigen::Vector2d innov(e1.dot(c), e2.dot(c));
  const double r = in.tilt_sigma * in.tilt_sigma / in.dt_s * in.tilt_var_scale;
  fuse<2>(h, innov, Eigen::Vector2d::Constant(r), kReportGateSigma, false, st);
  record(st, Decision::kFused, in.stamp_ns, first_pass);
}

void SelectiveEkf::process_heading(const ImuInput& in, bool first_pass, bool anchored) {
  const int64_t now = in.stamp_ns;
  SourceStatus& sh = status_[static_cast<size_t>(SelectiveEkfAid::kMagHeading)];
  if (!in.has_mag || !(in.dt_s > 0.0)) {
    record(sh, Decision::kRejectedNoMag, now, first_pass);
    return;
  }
  // dpsi: the rotation about world up taking the horizontal part of R(q) m onto magnetic north
  // (+y ENU); a world-frame rotation dpsi e_z is the body-frame rotation dpsi u.
  const Eigen::Vector3d mw = x_.q_world_body * in.mag;
  const double horiz = std::hypot(mw.x(), mw.y());
  if (!(horiz > 1e-3 * in.mag.norm())) {
    record(sh, Decision::kRejectedBadInput, now, first_pass);  // field vertical: no heading
    return;
  }
  const double dpsi = wrap_angle(0.5 * kPi - std::atan2(mw.y(), mw.x()));
  const Eigen::Vector3d u = x_.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
  const bool trusted = mag_trusted(in, u, std::abs(dpsi), anchored, first_pass);
  Eigen::Matrix<double, 1, kN> h = Eigen::Matrix<double, 1, kN>::Zero();
  h.block<1, 3>(0, kTh) = u.transpose();
  double r = p_.sigma_heading_rad_sqrt_s * p_.sigma_heading_rad_sqrt_s / in.dt_s;
  if (p_.heading_disturbance_weight > 0.0 && std::isfinite(x_.field_gate.last_norm_ut)) {
    const double rn = x_.field_gate.norm_ratio(gp_);
    const double rd = x_.field_gate.dip_ratio();
    r *= 1.0 + p_.heading_disturbance_weight * (rn * rn + rd * rd);
  }
  const Eigen::Matrix<double, 1, 1> innov(dpsi);
  if (!trusted && p_.action == ImuQuatAction::kDrop) {
    fuse<1>(h, innov, Eigen::Matrix<double, 1, 1>(r), kReportGateSigma, false, sh, true);
    record(sh, mag_.quat_error_test_failed && !mag_.angle_test_failed && !mag_.norm_test_failed
                   ? Decision::kRejectedQuatError
                   : Decision::kRejectedDisturbance,
           now, first_pass);
    return;
  }
  if (!trusted) {
    r *= p_.inflate_factor;
  }
  fuse<1>(h, innov, Eigen::Matrix<double, 1, 1>(r), kReportGateSigma, false, sh);
  record(sh, trusted ? Decision::kFused : Decision::kFusedInflated, now, first_pass);
}

void SelectiveEkf::process_vision(const VisionPose& v, bool first_pass) {
  const int64_t now = v.capture_stamp_ns;
  const Eigen::Quaterniond q_meas =
      (v.q_world_camera.normalized() * p_.q_body_camera.conjugate()).normalized();
  const double sr = std::isfinite(v.sigma_rad) && v.sigma_rad > 0.0 ? v.sigma_rad
                                                                    : p_.sigma_vision_deg * kRadPerDeg;
  const double sm = std::isfinite(v.sigma_m) && v.sigma_m > 0.0 ? v.sigma_m : p_.sigma_vision_m;
  SourceStatus& sa = status_[static_cast<size_t>(SelectiveEkfAid::kVisionAttitude)];
  SourceStatus& sp = status_[static_cast<size_t>(SelectiveEkfAid::kVisionPosition)];

  auto reset_attitude = [&]() {
    x_.q_world_body = q_meas;
    x_.P.middleRows<3>(kTh).setZero();
    x_.P.middleCols<3>(kTh).setZero();
    x_.P.block<3, 3>(kTh, kTh) = Eigen::Matrix3d::Identity() * sr * sr;
    x_.vision_aligned = true;
    x_.vision_consecutive_rejects = 0;
    x_.last_vision_fused_ns = now;
    x_.q_error_fail_since_ns = -1;
    record(sa, Decision::kReset, now, first_pass);
  };
  if (!x_.vision_aligned) {
    reset_attitude();
  } else {
    const Eigen::Quaterniond qa = quat_align_sign(q_meas, x_.q_world_body);
    const Eigen::Vector3d innov = quat_log(x_.q_world_body.conjugate() * qa);
    Eigen::Matrix<double, 3, kN> h = Eigen::Matrix<double, 3, kN>::Zero();
    h.middleCols<3>(kTh).setIdentity();
    if (fuse<3>(h, innov, Eigen::Vector3d::Constant(sr * sr), p_.vision_gate_sigma, true, sa)) {
      x_.vision_consecutive_rejects = 0;
      x_.last_vision_fused_ns = now;
      record(sa, Decision::kFused, now, first_pass);
    } else if (++x_.vision_consecutive_rejects >= p_.vision_reset_after_rejections) {
      reset_attitude();
    } else {
      record(sa, Decision::kRejectedGate, now, first_pass);
    }
  }

  if (!v.has_position) {
    return;
  }
  const Eigen::Matrix3d rot = x_.q_world_body.toRotationMatrix();
  if (!x_.position_aligned) {
    x_.t_m = v.p_world_camera_m - rot * p_.p_body_camera_m;
    x_.v_mps.setZero();
    x_.P.middleRows<3>(kT).setZero();
    x_.P.middleCols<3>(kT).setZero();
    x_.P.block<3, 3>(kT, kT) = Eigen::Matrix3d::Identity() * sm * sm;
    x_.position_aligned = true;
    record(sp, Decision::kReset, now, first_pass);
    return;
  }
  // H = [0  -R [p_body_cam x]  0  I  0] (the attitude block is zero without a lever arm)
  Eigen::Matrix<double, 3, kN> h = Eigen::Matrix<double, 3, kN>::Zero();
  h.middleCols<3>(kTh) = J_rotate_right_perturbation(x_.q_world_body, p_.p_body_camera_m);
  h.middleCols<3>(kT).setIdentity();
  const Eigen::Vector3d innov = v.p_world_camera_m - (x_.t_m + rot * p_.p_body_camera_m);
  if (fuse<3>(h, innov, Eigen::Vector3d::Constant(sm * sm), p_.vision_gate_sigma, true, sp)) {
    x_.vision_pos_consecutive_rejects = 0;
    record(sp, Decision::kFused, now, first_pass);
  } else if (++x_.vision_pos_consecutive_rejects >= p_.vision_reset_after_rejections) {
    x_.position_aligned = false;  // re-anchored on the next measurement
    x_.vision_pos_consecutive_rejects = 0;
    record(sp, Decision::kRejectedGate, now, first_pass);
  } else {
    record(sp, Decision::kRejectedGate, now, first_pass);
  }
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

void SelectiveEkf::preprocess(ImuInput& in) {
  // Part of the state (x_.pre), so a replay after a late vision frame re-derives it exactly.
  SelectiveEkfPreState& pre = x_.pre;
  const double dt_s = in.dt_s;
  if (!(dt_s > 0.0)) {
    pre = SelectiveEkfPreState{};
    pre.lp_accel_i = in.accel;
    pre.rest_detector.start(in.gyro, in.accel);
    in.up_meas = in.accel.normalized();
    return;
  }
  // Accelerometer low-pass in the gyro-propagated (bias-corrected) frame: gravity does not move
  // there, external accelerations average out.
  pre.q_ib = (pre.q_ib * quat_exp((in.gyro - x_.b_rps) * dt_s)).normalized();
  const double k = p_.accel_lowpass_tau_s > 0.0 ? dt_s / (p_.accel_lowpass_tau_s + dt_s) : 1.0;
  pre.lp_accel_i += k * (pre.q_ib * in.accel - pre.lp_accel_i);
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

bool SelectiveEkf::update_imu(const ImuSample& s) {
  const SampleCheck c = check_imu_sample(s, last_imu_stamp_ns_, p_.limits, rejections_, p_.use_magnetometer);
  if (anchor_.reanchor(c, s.stamp_ns, p_.limits.max_dt_s)) {
    // Confirmed time jump: keep the state, restart time here; the history cannot span it.
    last_imu_stamp_ns_ = s.stamp_ns;
    x_.stamp_ns = s.stamp_ns - imu_delay_ns_;
    history_.clear();
    vision_log_.clear();
    return false;
  }
  if (!c.accept) {
    return false;
  }
  ImuInput in;
  in.stamp_ns = s.stamp_ns - imu_delay_ns_;  // state time: when the measured motion happened
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
  SourceStatus& sa = status_[static_cast<size_t>(SelectiveEkfAid::kVisionAttitude)];
  if (!finite_quat(v_in.q_world_camera) || v_in.capture_stamp_ns < 0 ||
      (v_in.has_position && !v_in.p_world_camera_m.allFinite()) ||
      (std::isfinite(v_in.sigma_rad) && v_in.sigma_rad <= 0.0) ||
      (std::isfinite(v_in.sigma_m) && v_in.sigma_m <= 0.0)) {
    ++vc_.bad_input;
    record(sa, Decision::kRejectedBadInput, v_in.capture_stamp_ns, true);
    return false;
  }
  if (!initialized_ || history_.empty()) {
    ++vc_.before_init;
    record(sa, Decision::kRejectedBadInput, v_in.capture_stamp_ns, true);
    return false;
  }
  if (v_in.capture_stamp_ns < history_.front().input.stamp_ns) {
    ++vc_.too_old;
    record(sa, Decision::kRejectedTooOld, v_in.capture_stamp_ns, true);
    return false;
  }
  VisionPose v = v_in;
  v.q_world_camera.normalize();
  v.capture_stamp_ns += seconds_to_ns(p_.vision_time_offset_s);  // onto the IMU clock
  if (v.capture_stamp_ns < history_.front().input.stamp_ns) {
    ++vc_.too_old;
    record(sa, Decision::kRejectedTooOld, v.capture_stamp_ns, true);
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
  const int64_t state_now_ns = last_imu_stamp_ns_ - imu_delay_ns_;
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
  return all_finite(x_.w_rps, x_.q_world_body.coeffs(), x_.b_rps, x_.t_m, x_.v_mps, out_q_.coeffs()) &&
         covariance_ok(x_.P, full);
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
      record(st, Decision::kRejectedStateReset, stamp_ns, true);
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
