// ParallelKf::update() and the per-source report (kept apart from the filter's mathematics in
// parallel_kf.cpp: the step records what it did with each input, this file turns it into the
// SourceReport shape of poise/core/source_report.h).
#include "poise/parallel_kf/parallel_kf.h"

#include <algorithm>
#include <cmath>

namespace poise {

bool ParallelKf::update(const ImuSample& s) {
  const bool was_initialized = s_.initialized;
  mag_use_ = MagUse::kNone;
  gate_norm_ut_ = std::nan("");
  SampleCheck c;
  const bool accepted = step(s, c);
  if (accepted && !healthy()) {
    reset_unhealthy();
    return false;
  }
  report(s, c, accepted, was_initialized);
  return accepted;
}

bool ParallelKf::healthy() {
  // per sample: one sum over the state and the three covariances' diagonals, and their signs;
  // every kFullCheckEvery-th sample the full check of each covariance (state_health.h)
  const auto& p1 = s_.kf1.covariance();
  const auto& p2 = s_.kf2.covariance();
  if (!all_finite(s_.kf1.up_body(), s_.kf1.ext_accel_body(), s_.kf2.u(), s_.kf2.e(), s_.bias, s_.lp_accel_i,
                  s_.gate.m_ut, s_.gate.dip_rad, p1.diagonal(), p2.diagonal(), s_.bias_cov.diagonal()) ||
      !(std::min({p1.diagonal().minCoeff(), p2.diagonal().minCoeff(), s_.bias_cov.diagonal().minCoeff()}) >= 0.0)) {
    return false;
  }
  return !s_.health.full_due() ||
         (covariance_ok(p1, true) && covariance_ok(p2, true) && covariance_ok(s_.bias_cov, true));
}

void ParallelKf::reset_unhealthy() {
  const SourceReport gyro = gyro_src_;  // reports are the filter's, not its state's
  const SourceReport accel = accel_src_;
  const SourceReport mag = mag_src_;
  using S = ParallelKfState;
  const FieldGate gate = s_.gate;  // its counters are kept, its reference is learnt again
  reset_keeping(s_, [this] { reset(); }, &S::rejections);
  s_.gate.gated = gate.gated;
  s_.gate.forced = gate.forced;
  s_.gate.reacquired = gate.reacquired;
  gyro_src_ = gyro;
  accel_src_ = accel;
  mag_src_ = mag;
  for (SourceReport* r : {&gyro_src_, &accel_src_, &mag_src_}) {
    r->mark_rejected(kStateResetReason);
  }
}

void ParallelKf::reset_report() {
  mag_use_ = MagUse::kNone;
  gate_norm_ut_ = std::nan("");
  gyro_src_ = SourceReport(Source::kGyro);
  accel_src_ = SourceReport(Source::kAccel);
  mag_src_ = SourceReport(Source::kMag);
}

void ParallelKf::report(const ImuSample& s, const SampleCheck& c, bool accepted, bool was_initialized) {
  if (!accepted) {
    const char* why = to_string(c.reject);
    gyro_src_.mark_rejected(why);
    accel_src_.mark_rejected(why);
    mag_src_.mark_rejected(why);
    return;
  }
  if (was_initialized) {
    gyro_src_.mark_fused(s.stamp_ns);
  } else {
    gyro_src_.mark_not_available("initialising");
  }

  accel_src_.mark_fused(s.stamp_ns);

  // KF2's magnetometer
  if (!c.mag_ok) {
    if (c.mag_reject != RejectReason::kCount) {
      mag_src_.mark_rejected(to_string(c.mag_reject));
    } else {
      mag_src_.mark_not_available(c.mag_absent);  // none in the sample, or use_magnetometer: false
    }
    return;
  }
  switch (mag_use_) {
    case MagUse::kGated: mag_src_.mark_rejected("disturbed"); return;
    case MagUse::kForced: mag_src_.mark_fused(s.stamp_ns, "forced_after_max_reject"); return;
    case MagUse::kLearning: mag_src_.mark_not_available("learning_field"); return;
    case MagUse::kNone: break;
  }
  if (s_.out.mag_used) {
    mag_src_.mark_fused(s.stamp_ns);
  } else {
    mag_src_.mark_not_available(was_initialized ? "not_used" : "initialising");
  }
}

SourceReports ParallelKf::sources() const {
  SourceReports out{gyro_src_, accel_src_, mag_src_};
  SourceReport& accel = out[1];
  if (accel.fused()) {
    // KF1: H1 = [g I | I], M1 = sigma_A^2 I (7f), (7h)
    const Eigen::Matrix<double, 6, 6>& p1 = s_.kf1.covariance();
    const double g = p_.tilt.gravity_mps2;
    InnovationVector var_a(3);
    for (int i = 0; i < 3; ++i) {
      var_a[i] = g * g * p1(i, i) + 2.0 * g * p1(i, 3 + i) + p1(3 + i, 3 + i) +
                 p_.tilt.sigma_accel_mps2 * p_.tilt.sigma_accel_mps2;
    }
    accel.set_innovation(s_.kf1.last_innovation(), var_a);
  }
  SourceReport& mag = out[2];
  if (mag.decision != SourceDecision::kNotAvailable && std::isfinite(gate_norm_ut_)) {
    // The gate as a measurement: [|s_M| - m, dip - alpha] against the tolerances.
    const double dip = std::asin(std::clamp(gate_sin_dip_, -1.0, 1.0));
    const double tol_norm_ut = p_.mag_norm_tol * s_.gate.m_ut;
    const double tol_dip_rad = p_.mag_dip_tol_deg * kRadPerDeg;
    InnovationVector innov(2);
    innov << gate_norm_ut_ - s_.gate.m_ut, dip - s_.gate.dip_rad;
    InnovationVector var(2);
    var << tol_norm_ut * tol_norm_ut, tol_dip_rad * tol_dip_rad;
    mag.set_innovation(innov, var);
  }
  return out;
}

}  // namespace poise
