#include "poise/selective_ekf/selective_ekf.h"

#include <algorithm>
#include <stdexcept>

namespace poise {
namespace {

constexpr double kNsToS = 1e-9;
/// Gate used only to report a test ratio for sources that are never gated (gyro, q_imu), sigma.
constexpr double kReportGateSigma = 5.0;

int64_t seconds_to_ns(double s) { return static_cast<int64_t>(std::llround(s * 1e9)); }

bool finite_quat(const Eigen::Quaterniond& q) {
  return q.coeffs().allFinite() && q.coeffs().norm() > 0.5 && q.coeffs().norm() < 1.5;
}

}  // namespace

const char* to_string(Source s) {
  switch (s) {
    case Source::kGyro: return "gyro";
    case Source::kImuQuat: return "imu_quat";
    case Source::kVisionAttitude: return "vision_attitude";
    case Source::kVisionPosition: return "vision_position";
    case Source::kCount: break;
  }
  return "unknown";
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
    case Decision::kCount: break;
  }
  return "unknown";
}

void validate(const SelectiveEkfParams& p) {
  auto need = [](bool ok, const char* what) {
    if (!ok) {
      throw std::invalid_argument(std::string("SelectiveEkfParams: ") + what);
    }
  };
  need(p.sigma_angular_accel > 0.0, "sigma_angular_accel must be > 0");
  need(p.sigma_linear_accel > 0.0, "sigma_linear_accel must be > 0");
  need(p.sigma_attitude_walk >= 0.0, "sigma_attitude_walk must be >= 0");
  need(p.sigma_gyro_rps > 0.0, "sigma_gyro_rps must be > 0");
  need(p.sigma_imu_quat_deg > 0.0, "sigma_imu_quat_deg must be > 0");
  need(p.sigma_vision_deg > 0.0, "sigma_vision_deg must be > 0");
  need(p.sigma_vision_m > 0.0, "sigma_vision_m must be > 0");
  need(!std::isfinite(p.dip_deg) || std::abs(p.dip_deg) <= 90.0, "dip_deg must be in [-90, 90]");
  need(std::isnan(p.dip_deg) || std::isfinite(p.dip_deg), "dip_deg must be finite or NaN");
  need(p.startup_samples >= 1, "startup_samples must be >= 1");
  need(p.disturbance_angle_threshold_deg > 0.0, "disturbance_angle_threshold_deg must be > 0");
  need(p.mag_norm_threshold > 0.0, "mag_norm_threshold must be > 0");
  need(p.quat_error_threshold_deg > 0.0 && p.quat_error_threshold_deg <= 180.0,
       "quat_error_threshold_deg must be in (0, 180]");
  need(p.inflate_factor >= 1.0, "inflate_factor must be >= 1");
  need(p.untrusted_hold_s >= 0.0, "untrusted_hold_s must be >= 0");
  need(p.q_error_lockout_s > 0.0, "q_error_lockout_s must be > 0");
  need(p.vision_anchor_s > 0.0, "vision_anchor_s must be > 0");
  need(p.vision_gate_sigma > 0.0, "vision_gate_sigma must be > 0");
  need(p.vision_reset_after_rejections >= 1, "vision_reset_after_rejections must be >= 1");
  need(p.history_s > 0.0 && p.history_s <= 5.0, "history_s must be in (0, 5]");
  need(std::abs(p.vision_time_offset_s) <= 0.2, "vision_time_offset_s must be in [-0.2, 0.2]");
  need(p.imu_delay_s >= 0.0 && p.imu_delay_s <= 0.05, "imu_delay_s must be in [0, 0.05]");
  need(finite_quat(p.q_body_camera), "q_body_camera must be a finite unit quaternion");
  need(p.p_body_camera_m.allFinite(), "p_body_camera_m must be finite");
  need(p.init_sigma_attitude_deg > 0.0 && p.init_sigma_rate_rps > 0.0 &&
           p.init_sigma_position_m > 0.0 && p.init_sigma_velocity_mps > 0.0,
       "init_sigma_* must be > 0");
}

SelectiveEkf::SelectiveEkf(const SelectiveEkfParams& params) : p_(params), gn_(params.gauss_newton) {
  validate(p_);
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
  x_.P.setZero();
  const double sa = p_.init_sigma_attitude_deg * kRadPerDeg;
  x_.P.diagonal().segment<3>(kW).setConstant(p_.init_sigma_rate_rps * p_.init_sigma_rate_rps);
  x_.P.diagonal().segment<3>(kTh).setConstant(sa * sa);
  x_.P.diagonal().segment<3>(kT).setConstant(p_.init_sigma_position_m * p_.init_sigma_position_m);
  x_.P.diagonal().segment<3>(kV).setConstant(p_.init_sigma_velocity_mps *
                                              p_.init_sigma_velocity_mps);
  initialized_ = false;
  last_imu_stamp_ns_ = -1;
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
}

Eigen::Quaterniond SelectiveEkf::q_world_body() const {
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
  // F is block-diagonal between [w, th] and [t, v]; while P has no cross-covariance between the
  // two (no lever-arm position fix yet, x_.coupled false) each 6x6 block is propagated alone.
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
    x_.P = apply_f(fp.transpose());
  } else {
    using Mat6 = Eigen::Matrix<double, 6, 6>;
    Mat6 att = x_.P.topLeftCorner<6, 6>();  // [w, th]: th' = a th + b w
    auto apply_att = [&](const Mat6& m) {
      Mat6 out = m;
      out.bottomRows<3>() = a * m.bottomRows<3>() + b * m.topRows<3>();
      return out;
    };
    const Mat6 fa = apply_att(att);
    x_.P.topLeftCorner<6, 6>() = apply_att(fa.transpose());
    Mat6 tr = x_.P.bottomRightCorner<6, 6>();  // [t, v]: t' = t + h v
    tr.topRows<3>() += h * tr.bottomRows<3>();
    tr.leftCols<3>() += h * tr.rightCols<3>();
    x_.P.bottomRightCorner<6, 6>() = tr;
  }
  const double qw = p_.sigma_angular_accel * p_.sigma_angular_accel * h;
  const double qth = p_.sigma_attitude_walk * p_.sigma_attitude_walk * h;
  const double qv = p_.sigma_linear_accel * p_.sigma_linear_accel * h;
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
    x_.P(kV + i, kV + i) += qv;
    x_.P(kT + i, kT + i) += qv * h * h / 3.0;
    x_.P(kV + i, kT + i) += qc_v;
    x_.P(kT + i, kV + i) += qc_v;
  }
  x_.stamp_ns = stamp_ns;
}

// ------------------------------------------------------------------------------------ update
namespace {

/// Joseph-form update of 3 rows on an N-state covariance `p`: H = [I at column `col`] plus `h_th`
/// at column `th_col` when non-null. H P and P H^T are then column blocks of P, so every product
/// is Nx3 or 3x3. Leaves `p` and `dx` untouched when the gate rejects.
template <int N>
double joseph3(Eigen::Matrix<double, N, N>& p, int col, const Eigen::Matrix3d* h_th, int th_col,
               const Eigen::Vector3d& innov, const Eigen::Vector3d& r_diag, double gate_sigma, bool gate,
               SourceStatus& st, bool* accepted, Eigen::Matrix<double, N, 1>& dx) {
  using MatN3 = Eigen::Matrix<double, N, 3>;
  MatN3 pht = p.template middleCols<3>(col);  // P H^T
  if (h_th != nullptr) {
    pht.noalias() += p.template middleCols<3>(th_col).lazyProduct(h_th->transpose());
  }
  auto h_times = [&](const MatN3& m) {  // H m
    Eigen::Matrix3d out = m.template middleRows<3>(col);
    if (h_th != nullptr) {
      out.noalias() += h_th->lazyProduct(m.template middleRows<3>(th_col));
    }
    return out;
  };
  Eigen::Matrix3d s = h_times(pht);
  s.diagonal() += r_diag;
  double ratio = 0.0;
  for (int i = 0; i < 3; ++i) {
    ratio = std::max(ratio, innov[i] * innov[i] / (gate_sigma * gate_sigma * s(i, i)));
  }
  st.innovation = innov;
  st.innovation_variance = s.diagonal();
  st.test_ratio = ratio;
  if (gate && !(ratio <= 1.0)) {
    *accepted = false;
    return ratio;
  }
  const MatN3 k = pht.lazyProduct(s.inverse());  // (5)
  dx = k.lazyProduct(innov);                     // (6)
  // Joseph form of (7): P = (I - K H) P (I - K H)^T + K R K^T, using H P = (P H^T)^T.
  Eigen::Matrix<double, N, N> ap = p;
  ap.noalias() -= k.lazyProduct(pht.transpose());  // (I - K H) P
  MatN3 apht = ap.template middleCols<3>(col);      // (I - K H) P H^T
  if (h_th != nullptr) {
    apht.noalias() += ap.template middleCols<3>(th_col).lazyProduct(h_th->transpose());
  }
  ap.noalias() -= apht.lazyProduct(k.transpose());
  const MatN3 kr = k * r_diag.asDiagonal();
  ap.noalias() += kr.lazyProduct(k.transpose());
  p = 0.5 * (ap + ap.transpose());
  *accepted = true;
  return ratio;
}

}  // namespace

double SelectiveEkf::fuse3(int col, const Eigen::Matrix3d* h_th, const Eigen::Vector3d& innov,
                           const Eigen::Vector3d& r_diag, double gate_sigma, bool gate,
                           SourceStatus& st, bool* accepted) {
  Vec dx = Vec::Zero();
  double ratio = 0.0;
  if (h_th == nullptr && !x_.coupled) {
    // No cross-covariance between [w, th] and [t, v]: the rows touch one 6x6 block only (the
    // rest of K is exactly zero), a quarter of the 12-state work with the same result.
    const int base = col < kT ? 0 : kT;
    Eigen::Matrix<double, 6, 6> block = x_.P.block<6, 6>(base, base);
    Eigen::Matrix<double, 6, 1> dx6;
    ratio = joseph3<6>(block, col - base, nullptr, 0, innov, r_diag, gate_sigma, gate, st, accepted, dx6);
    if (*accepted) {
      x_.P.block<6, 6>(base, base) = block;
      dx.segment<6>(base) = dx6;
    }
  } else {
    if (h_th != nullptr) {
      x_.coupled = true;  // a lever-arm position fix correlates attitude and position from now on
    }
    ratio = joseph3<kN>(x_.P, col, h_th, kTh, innov, r_diag, gate_sigma, gate, st, accepted, dx);
  }
  if (*accepted) {
    inject(dx);
  }
  return ratio;
}

void SelectiveEkf::inject(const Vec& dx) {
  x_.w_rps += dx.segment<3>(kW);
  x_.q_world_body = (x_.q_world_body * quat_exp(dx.segment<3>(kTh))).normalized();
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

void SelectiveEkf::process_imu(const ImuInput& in, bool first_pass) {
  const int64_t now = in.stamp_ns;
  // Gyro rows: y = w.
  {
    const double r = p_.sigma_gyro_rps * p_.sigma_gyro_rps;
    bool ok = false;
    fuse3(kW, nullptr, in.gyro - x_.w_rps, Eigen::Vector3d::Constant(r), kReportGateSigma, false,
          status_[static_cast<size_t>(Source::kGyro)], &ok);
    record(status_[static_cast<size_t>(Source::kGyro)], Decision::kFused, now, first_pass);
  }

  SourceStatus& sq = status_[static_cast<size_t>(Source::kImuQuat)];
  if (!in.has_q_imu) {
    record(sq, Decision::kRejectedNoMag, now, first_pass);
    return;
  }
  // Disturbance angle (8) and quaternion error (9)-(10).
  // The filtered up axis is only as good as the tilt: without a recent vision fix the tilt is
  // carried by the gyro alone (q_imu gated), and a drifting tilt would keep the test failing
  // (self-locking), so the raw accelerometer is used until vision anchors the attitude again.
  const bool anchored = x_.last_vision_fused_ns >= 0 &&
                        now - x_.last_vision_fused_ns <= seconds_to_ns(p_.vision_anchor_s);
  Eigen::Vector3d up = in.accel;
  if (p_.up_source == UpSource::kFiltered && anchored) {
    up = x_.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
  }
  const double theta_m = angle_between_vectors(in.mag, up);                 // (8)
  const double theta_q = quat_angle_between(x_.q_world_body, in.q_imu);     // (9)-(10)
  mag_.disturbance_angle_deg = theta_m * kDegPerRad;
  mag_.quat_error_deg = theta_q * kDegPerRad;
  mag_.angle_test_failed =
      mag_.reference_ready &&
      std::abs(theta_m - ref_angle_rad_) > p_.disturbance_angle_threshold_deg * kRadPerDeg;
  mag_.norm_test_failed = false;
  if (p_.mag_norm_test && ref_norm_ut_ > 0.0) {
    mag_.norm_ratio = in.mag.norm() / ref_norm_ut_;
    mag_.norm_test_failed = std::abs(mag_.norm_ratio - 1.0) > p_.mag_norm_threshold;
  }
  bool q_fail = p_.quat_error_test && theta_q > p_.quat_error_threshold_deg * kRadPerDeg;
  if (q_fail) {
    if (x_.q_error_fail_since_ns < 0) {
      x_.q_error_fail_since_ns = now;
    }
    if (!anchored && now - x_.q_error_fail_since_ns > seconds_to_ns(p_.q_error_lockout_s)) {
      q_fail = false;  // lock-out release: the prediction, not q_imu, may have drifted
    }
  } else {
    x_.q_error_fail_since_ns = -1;
  }
  mag_.quat_error_test_failed = q_fail;
  const bool disturbed = mag_.angle_test_failed || mag_.norm_test_failed || q_fail;
  if (p_.gating_enabled && disturbed) {
    x_.untrusted_until_ns = now + seconds_to_ns(p_.untrusted_hold_s);
  }
  const bool trusted = !p_.gating_enabled || x_.untrusted_until_ns < 0 || now >= x_.untrusted_until_ns;
  mag_.trusted = trusted;
  if (!trusted && first_pass) {
    ++mag_.untrusted_samples;
  }
  const Decision reject_reason = (mag_.angle_test_failed || mag_.norm_test_failed || !q_fail)
                                     ? Decision::kRejectedDisturbance
                                     : Decision::kRejectedQuatError;

  const Eigen::Quaterniond qm = quat_align_sign(in.q_imu, x_.q_world_body);
  const Eigen::Vector3d innov = quat_log(x_.q_world_body.conjugate() * qm);
  const double sig = p_.sigma_imu_quat_deg * kRadPerDeg;
  double r = sig * sig;
  if (!trusted && p_.action == ImuQuatAction::kDrop) {
    // Report the innovation the rows would have had, then leave them out.
    Eigen::Matrix3d s = x_.P.block<3, 3>(kTh, kTh);
    s.diagonal().array() += r;
    sq.innovation = innov;
    sq.innovation_variance = s.diagonal();
    sq.test_ratio = 0.0;
    for (int i = 0; i < 3; ++i) {
      sq.test_ratio = std::max(sq.test_ratio, innov[i] * innov[i] /
                                                  (kReportGateSigma * kReportGateSigma * s(i, i)));
    }
    record(sq, reject_reason, now, first_pass);
    return;
  }
  if (!trusted) {
    r *= p_.inflate_factor;
  }
  bool ok = false;
  fuse3(kTh, nullptr, innov, Eigen::Vector3d::Constant(r), kReportGateSigma, false, sq, &ok);
  record(sq, trusted ? Decision::kFused : Decision::kFusedInflated, now, first_pass);
}

void SelectiveEkf::process_vision(const VisionPose& v, bool first_pass) {
  const int64_t now = v.capture_stamp_ns;
  const Eigen::Quaterniond q_meas =
      (v.q_world_camera.normalized() * p_.q_body_camera.conjugate()).normalized();
  const double sr = std::isfinite(v.sigma_rad) && v.sigma_rad > 0.0 ? v.sigma_rad
                                                                    : p_.sigma_vision_deg * kRadPerDeg;
  const double sm = std::isfinite(v.sigma_m) && v.sigma_m > 0.0 ? v.sigma_m : p_.sigma_vision_m;
  SourceStatus& sa = status_[static_cast<size_t>(Source::kVisionAttitude)];
  SourceStatus& sp = status_[static_cast<size_t>(Source::kVisionPosition)];

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
    bool ok = false;
    fuse3(kTh, nullptr, innov, Eigen::Vector3d::Constant(sr * sr), p_.vision_gate_sigma, true, sa, &ok);
    if (ok) {
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
  // H = [0  -R [p_body_cam x]  I  0]
  const Eigen::Matrix3d h_th = J_rotate_right_perturbation(x_.q_world_body, p_.p_body_camera_m);
  const bool lever = p_.p_body_camera_m.squaredNorm() > 0.0;
  const Eigen::Vector3d innov = v.p_world_camera_m - (x_.t_m + rot * p_.p_body_camera_m);
  bool ok = false;
  fuse3(kT, lever ? &h_th : nullptr, innov, Eigen::Vector3d::Constant(sm * sm), p_.vision_gate_sigma, true, sp, &ok);
  if (ok) {
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

bool SelectiveEkf::update_imu(const ImuSample& s) {
  const SampleCheck c = check_imu_sample(s, last_imu_stamp_ns_, p_.limits, rejections_);
  if (c.reanchor) {
    // Time gap: keep the state, restart time here; the history cannot span the gap.
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
  in.mag = s.mag_ut;
  if (c.mag_ok) {
    learn_reference(s);
    if (gn_.update(s)) {
      in.has_q_imu = true;
      in.q_imu = gn_.result().q_world_body;
    }
  }
  last_imu_stamp_ns_ = s.stamp_ns;
  if (!initialized_) {
    x_.q_world_body = in.has_q_imu ? in.q_imu
                                   : quat_from_two_vectors(in.accel, Eigen::Vector3d::UnitZ());
    x_.w_rps = in.gyro;
    x_.stamp_ns = in.stamp_ns;
    initialized_ = true;
    history_.push_back({in, x_});
    return true;
  }
  // Queued (future-stamped) vision strictly before this sample goes first, in stamp order.
  auto it = std::upper_bound(vision_log_.begin(), vision_log_.end(), history_.back().input.stamp_ns,
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
  // Trim the history to history_s (keep at least the newest entry) and the vision log with it.
  const int64_t oldest = in.stamp_ns - seconds_to_ns(p_.history_s);
  while (history_.size() > 1 && history_.front().input.stamp_ns < oldest) {
    history_.pop_front();
  }
  while (!vision_log_.empty() &&
         vision_log_.front().capture_stamp_ns < history_.front().input.stamp_ns) {
    vision_log_.pop_front();
  }
  return true;
}

bool SelectiveEkf::update_vision(const VisionPose& v_in) {
  ++vc_.received;
  SourceStatus& sa = status_[static_cast<size_t>(Source::kVisionAttitude)];
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
  return true;
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
  for (size_t s = 0; s < static_cast<size_t>(Source::kCount); ++s) {
    const SourceStatus& st = ekf_.status(static_cast<Source>(s));
    for (size_t d = 0; d < st.by_decision.size(); ++d) {
      const auto dec = static_cast<Decision>(d);
      if (dec != Decision::kFused && dec != Decision::kFusedInflated && dec != Decision::kNone &&
          dec != Decision::kReset) {
        put(std::string(to_string(static_cast<Source>(s))) + "_" + to_string(dec),
            st.by_decision[d]);
      }
    }
  }
  return m;
}

}  // namespace poise
