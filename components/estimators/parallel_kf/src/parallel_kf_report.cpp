// ParallelKf::update() and the per-source report (kept apart from the filter's mathematics in
// parallel_kf.cpp: the step records what it did with each input, this file turns it into the
// SourceReport shape of poise/core/source_report.h).
#include "poise/parallel_kf/parallel_kf.h"

#include <algorithm>
#include <cmath>

namespace poise {

bool ParallelKf::update(const ImuSample& s) {
  const bool was_initialized = s_.initialized;
  s_.mag_use = ParallelKfState::MagUse::kNone;
  s_.gate_norm_ut = std::nan("");
  SampleCheck c;
  const bool accepted = step(s, c);
  if (accepted && !healthy()) {
    reset_unhealthy();
    return false;
  }
  if (accepted) {
    update_attitude();  // a refused sample leaves sZ, sX' and the gyro as they were
  }
  report(s, c, accepted, was_initialized);
  return accepted;
}

bool ParallelKf::healthy() {
  // per sample: one sum over the state and the three covariances' diagonals, and their signs;
  // every kFullCheckEvery-th sample the full check of each covariance (state_health.h)
  // (the KFs' variances without writing their implicit blocks: DirectionKf::variances_ok)
  if (!all_finite(s_.kf1.up_body(), s_.kf1.ext_accel_body(), s_.kf2.u(), s_.kf2.e(), s_.bias, s_.lp_accel_i,
                  s_.gate.m_ut, s_.gate.dip_rad, s_.bias_cov.diagonal()) ||
      !(s_.bias_cov.diagonal().minCoeff() >= 0.0) || !s_.kf1.direction_kf().variances_ok() ||
      !s_.kf2.variances_ok()) {
    return false;
  }
  return !s_.health.full_due() || (covariance_ok(s_.kf1.covariance(), true) &&
                                   covariance_ok(s_.kf2.covariance(), true) && covariance_ok(s_.bias_cov, true));
}

void ParallelKf::reset_unhealthy() {
  using S = ParallelKfState;
  const FieldGate gate = s_.gate;  // its counters are kept, its reference is learnt again
  reset_keeping(s_, [this] { reset(); }, &S::rejections, &S::gyro_src, &S::accel_src, &S::mag_src,
                &S::mag_corrected_count, &S::rest_turns_reverted);
  s_.gate.gated = gate.gated;
  s_.gate.forced = gate.forced;
  s_.gate.reacquired = gate.reacquired;
  s_.gate.offset_moves = gate.offset_moves;
  for (SourceReport* r : {&s_.gyro_src, &s_.accel_src, &s_.mag_src}) {
    r->mark_rejected(kStateResetReason);
  }
}

void ParallelKf::report(const ImuSample& s, const SampleCheck& c, bool accepted, bool was_initialized) {
  if (!accepted) {
    const char* why = to_string(c.reject);
    s_.gyro_src.mark_rejected(why);
    s_.accel_src.mark_rejected(why);
    s_.mag_src.mark_rejected(why);
    return;
  }
  if (was_initialized) {
    s_.gyro_src.mark_fused(s.stamp_ns);
  } else {
    s_.gyro_src.mark_not_available("initialising");
  }

  s_.accel_src.mark_fused(s.stamp_ns);

  // KF2's magnetometer
  if (!c.mag_ok) {
    if (c.mag_reject != RejectReason::kCount) {
      s_.mag_src.mark_rejected(to_string(c.mag_reject));
    } else {
      s_.mag_src.mark_not_available(c.mag_absent);  // none in the sample, or use_magnetometer: false
    }
    return;
  }
  using MagUse = ParallelKfState::MagUse;
  switch (s_.mag_use) {
    case MagUse::kGated: s_.mag_src.mark_rejected("disturbed"); return;
    case MagUse::kPending: s_.mag_src.mark_rejected("hard_iron_pending"); return;
    case MagUse::kMovedAtRest: s_.mag_src.mark_rejected("field_moved_at_rest"); return;
    case MagUse::kForced: s_.mag_src.mark_fused(s.stamp_ns, "forced_after_max_reject"); return;
    case MagUse::kLearning: s_.mag_src.mark_not_available("learning_field"); return;
    case MagUse::kRestarted: s_.mag_src.mark_fused(s.stamp_ns, "heading_restarted"); return;
    case MagUse::kNone: break;
  }
  if (s_.mag_used) {
    // fused after the hard-iron offset was removed from the reading (hard_iron): said so
    s_.mag_src.mark_fused(s.stamp_ns, s_.mag_corrected ? "hard_iron_corrected" : "");
  } else {
    s_.mag_src.mark_not_available(was_initialized ? "not_used" : "initialising");
  }
}

SourceReports ParallelKf::sources() const {
  SourceReports out{s_.gyro_src, s_.accel_src, s_.mag_src};
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
  if (mag.decision != SourceDecision::kNotAvailable && std::isfinite(s_.gate_norm_ut)) {
    // The gate as a measurement: [|s_M| - m, dip - alpha] against the tolerances.
    const double dip = std::asin(std::clamp(s_.gate_sin_dip, -1.0, 1.0));
    const double tol_norm_ut = p_.mag_norm_tol * s_.gate.m_ut;
    const double tol_dip_rad = p_.mag_dip_tol_deg * kRadPerDeg;
    InnovationVector innov(2);
    innov << s_.gate_norm_ut - s_.gate.m_ut, dip - s_.gate.dip_rad;
    InnovationVector var(2);
    var << tol_norm_ut * tol_norm_ut, tol_dip_rad * tol_dip_rad;
    mag.set_innovation(innov, var);
  }
  return out;
}

}  // namespace poise
