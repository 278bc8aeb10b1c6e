#include "poise/core/field_gate.h"

#include "poise/core/attitude.h"
#include "poise/core/params_check.h"

#include <algorithm>

namespace poise {
namespace {

bool earth_like(double norm_ut) { return norm_ut >= kEarthFieldMinUt && norm_ut <= kEarthFieldMaxUt; }

}  // namespace

void FieldGateParams::validate(const ParamCheck& check, const Keys& keys) const {
  check.require(std::isnan(field_magnitude_ut) || (std::isfinite(field_magnitude_ut) && field_magnitude_ut > 0.0),
                keys.field_magnitude_ut, "> 0 (uT) or null");
  check.require(std::isnan(dip_deg) || std::abs(dip_deg) < 90.0, keys.dip_deg, "in (-90, 90) (deg) or null");
  check.positive(startup_s, keys.startup_s, "s");
  check.non_negative(norm_tol, keys.norm_tol, "relative, 0 = no norm test");
  check.positive(dip_tol_deg, keys.dip_tol_deg, "deg");
  check.non_negative(reference_tau_s, keys.reference_tau_s, "s, 0 = fixed reference");
  check.non_negative(reacquire_s, keys.reacquire_s, "s, 0 = never");
  check.positive(reacquire_tol, keys.reacquire_tol, "relative");
  check.non_negative(max_reject_s, keys.max_reject_s, "s, 0 = never");
  check.non_negative(verify_s, keys.verify_s, "s, 0 = verified when learnt");
}

void FieldGate::reset(const FieldGateParams& p) {
  *this = FieldGate{};
  m_ut = std::isfinite(p.field_magnitude_ut) ? p.field_magnitude_ut : 0.0;
  dip_rad = std::isfinite(p.dip_deg) ? p.dip_deg * kRadPerDeg : 0.0;
  learnt = std::isfinite(p.field_magnitude_ut) && std::isfinite(p.dip_deg);
  verified = learnt;  // configured or from the magnetic model: trusted
}

void FieldGate::learn(const FieldGateParams& p, const Eigen::Vector3d& mag, const Eigen::Vector3d& up, double dt_s) {
  // Mean |s_M| and mean dip over the start-up window; and the moments offset_removed() needs.
  const double norm = mag.norm();
  learn_norm_sum += norm;
  learn_dip_sum += angle_between_vectors(up, mag) - 0.5 * kPi;
  const Eigen::Vector3d u = up.normalized();
  learn_field_sum += mag;
  learn_field2_sum += norm * norm;
  learn_up_field_sum += u.dot(mag);
  learn_up_sum += u;
  ++learn_n;
  learn_time_s += dt_s;
  if (!std::isfinite(p.field_magnitude_ut)) {
    m_ut = learn_norm_sum / learn_n;
  }
  if (!std::isfinite(p.dip_deg)) {
    dip_rad = learn_dip_sum / learn_n;
  }
  if (learn_time_s >= p.startup_s) {
    learnt = true;
    verified = !(p.verify_s > 0.0);
    consistent_s = 0.0;
    startup_reference = !std::isfinite(p.field_magnitude_ut) && !std::isfinite(p.dip_deg);
  }
}

double FieldGate::gate_ratio(const FieldGateParams& p, double norm, double sin_dip, double m, double dip) {
  const double dip_dev = std::abs(std::asin(std::clamp(sin_dip, -1.0, 1.0)) - dip) / (p.dip_tol_deg * kRadPerDeg);
  const double norm_dev = p.norm_tol > 0.0 ? std::abs(norm - m) / (p.norm_tol * m) : 0.0;
  return std::max(dip_dev, norm_dev);
}

OffsetJudgement FieldGate::offset_removed(const FieldGateParams& p, const Eigen::Vector3d& offset_ut,
                                          const Eigen::Vector3d& mag, const Eigen::Vector3d& up, double dt_s) {
  if (!startup_reference || offset_moved || !learnt || learn_n <= 0 || !p.enabled) {
    return OffsetJudgement::kNone;
  }
  const double norm = mag.norm();
  const double up_norm = up.norm();
  if (!(norm > 0.0) || !(up_norm > 0.0) || !(dt_s > 0.0) || !mag.allFinite() || !up.allFinite() ||
      !offset_ut.allFinite()) {
    return OffsetJudgement::kOpen;
  }
  offset_span_s += dt_s;
  offset_norm_sum += norm * dt_s;
  offset_sin_dip_sum += -up.dot(mag) / (norm * up_norm) * dt_s;
  if (offset_span_s < p.startup_s) {
    return OffsetJudgement::kOpen;
  }
  const double mean_norm = offset_norm_sum / offset_span_s;
  const double mean_sin_dip = offset_sin_dip_sum / offset_span_s;
  offset_span_s = 0.0;  // a span judged: the next starts from here
  offset_norm_sum = 0.0;
  offset_sin_dip_sum = 0.0;
  // the reference the start-up would have learnt without the offset: its mean of |s_M - b|^2 and
  // of -up . (s_M - b) (b fixed in the body)
  const double n = static_cast<double>(learn_n);
  const Eigen::Vector3d f0 = learn_field_sum / n;
  const double m2 = learn_field2_sum / n - 2.0 * f0.dot(offset_ut) + offset_ut.squaredNorm();
  const Eigen::Vector3d up0 = learn_up_sum / n;
  if (!(m2 > 0.0) || !std::isfinite(m2) || !(up0.norm() > 0.0)) {
    return OffsetJudgement::kOpen;
  }
  const double m_b = std::sqrt(m2);
  const double dip_b = std::asin(std::clamp(-(learn_up_field_sum / n - up0.dot(offset_ut)) / m_b, -1.0, 1.0));
  const double keep = gate_ratio(p, mean_norm, mean_sin_dip, m_ut, dip_rad);
  const double move = gate_ratio(p, mean_norm, mean_sin_dip, m_b, dip_b);
  if (!(std::min(keep, move) <= 1.0)) {
    return OffsetJudgement::kOpen;  // neither passes the gate: the field, or the offset's estimate, is off now
  }
  startup_reference = false;
  if (keep <= move) {
    return OffsetJudgement::kKept;  // the field without the offset is the one the start-up learnt
  }
  learnt_m_ut = m_ut;
  learnt_dip_rad = dip_rad;
  replace_reference(m_b, dip_b);
  offset_moved = true;
  moved_by_offset = true;
  ++offset_moves;
  // what the reference was following held the offset
  window_s = 0.0;
  accepted_s = 0.0;
  norm_sum = 0.0;
  sin_dip_sum = 0.0;
  return OffsetJudgement::kMoved;
}

void FieldGate::undo_offset() {
  offset_span_s = 0.0;
  offset_norm_sum = 0.0;
  offset_sin_dip_sum = 0.0;
  if (offset_moved) {
    replace_reference(learnt_m_ut, learnt_dip_rad);
    offset_moved = false;
    moved_by_offset = false;
    startup_reference = true;
  }
}

FieldVerdict FieldGate::step(const FieldGateParams& p, const Eigen::Vector3d& mag, const Eigen::Vector3d& up,
                             double dt_s) {
  last_norm_ut = std::nan("");
  if (!learnt) {
    learn(p, mag, up, dt_s);
    return FieldVerdict::kLearning;
  }
  if (moved_by_offset) {
    moved_by_offset = false;  // the heading restarts on this field (offset_removed judged the span before it)
    return FieldVerdict::kRelearnt;
  }
  if (!p.enabled) {
    if (!verified) {  // every field is accepted: a provisional reference is verified all the same
      consistent_s += dt_s;
      verified = consistent_s >= p.verify_s;
    }
    return FieldVerdict::kAccepted;
  }
  const double norm = mag.norm();
  // sin(dip) = -up . s_M / (|up| |s_M|); |dip - alpha| <= tol  <=>  sin(dip) within
  // [sin(alpha - tol), sin(alpha + tol)] (sin is monotonic on [-90, 90] deg): no asin per sample.
  const double sin_dip = -up.dot(mag) / (norm * up.norm());
  last_norm_ut = norm;
  last_sin_dip = sin_dip;
  if (dip_rad != bounds_dip) {
    const double tol = p.dip_tol_deg * kRadPerDeg;
    sin_lo = std::sin(std::max(dip_rad - tol, -0.5 * kPi));
    sin_hi = std::sin(std::min(dip_rad + tol, 0.5 * kPi));
    bounds_dip = dip_rad;
  }
  const bool disturbed =
      (p.norm_tol > 0.0 && std::abs(norm - m_ut) > p.norm_tol * m_ut) || sin_dip < sin_lo || sin_dip > sin_hi;
  if (!disturbed) {
    if (!verified) {
      consistent_s += dt_s;
      verified = consistent_s >= p.verify_s;
    }
    rejected_s = 0.0;
    cand_stable_s = 0.0;
    cand_norm = 0.0;
    if (p.reference_tau_s > 0.0) {  // what the reference follows (tick)
      norm_sum += norm * dt_s;
      sin_dip_sum += sin_dip * dt_s;
      accepted_s += dt_s;
    }
    return FieldVerdict::kAccepted;
  }
  if (p.max_reject_s > 0.0 && rejected_s >= p.max_reject_s) {
    ++forced;
    return FieldVerdict::kForced;
  }
  ++gated;
  rejected_s += dt_s;
  const bool provisional = !verified && p.verify_s > 0.0;
  if (p.reacquire_s > 0.0 || provisional) {
    // candidate for a new reference: norm and dip low-passed over 1 s, and how long they stayed
    // stable around that low-pass
    const double dip = std::asin(std::clamp(sin_dip, -1.0, 1.0));
    if (cand_norm <= 0.0) {
      cand_norm = norm;
      cand_dip = dip;
    }
    const double k = dt_s / (1.0 + dt_s);
    cand_norm += k * (norm - cand_norm);
    cand_dip += k * (dip - cand_dip);
    const bool stable = std::abs(norm - cand_norm) < p.reacquire_tol * cand_norm &&
                        std::abs(dip - cand_dip) < 0.5 * p.dip_tol_deg * kRadPerDeg;
    cand_stable_s = stable ? cand_stable_s + dt_s : 0.0;
    if (!stable && provisional) {
      // a provisional reference is replaced by a field steady from now on: the candidate starts
      // again here rather than dragging the changing field's past behind it
      cand_norm = norm;
      cand_dip = dip;
    }
    if (provisional && cand_stable_s >= p.startup_s && earth_like(cand_norm) &&
        (!earth_like(m_ut) || cand_stable_s > consistent_s)) {
      adopt_candidate();
      ++relearnt;
      consistent_s = 0.0;
      return FieldVerdict::kRelearnt;
    }
    if (p.reacquire_s > 0.0 && rejected_s >= p.reacquire_s && cand_stable_s >= p.reacquire_s) {
      adopt_candidate();
      ++reacquired;
    }
  }
  return FieldVerdict::kGated;
}

void FieldGate::adopt_candidate() {
  startup_reference = false;
  offset_moved = false;
  replace_reference(cand_norm, cand_dip);
}

void FieldGate::replace_reference(double m, double dip) {
  ++reference_epoch;
  m_ut = m;
  dip_rad = dip;
  rejected_s = 0.0;
  cand_stable_s = 0.0;
  cand_norm = 0.0;
}

void FieldGate::tick(const FieldGateParams& p, double dt_s) {
  if (!(p.reference_tau_s > 0.0)) {
    return;
  }
  window_s += dt_s;
  if (window_s >= kFieldGateWindowS) {
    follow(p);
  }
}

void FieldGate::follow(const FieldGateParams& p) {
  // The reference norm and dip follow the field the gate accepted (never the gated samples), with
  // time constant reference_tau_s over accepted time.
  if (accepted_s > 0.0) {
    const double k = accepted_s / (p.reference_tau_s + accepted_s);
    const double norm = norm_sum / accepted_s;
    const double sin_dip = std::clamp(sin_dip_sum / accepted_s, -1.0, 1.0);
    m_ut += k * (norm - m_ut);
    dip_rad += k * (std::asin(sin_dip) - dip_rad);
  }
  window_s = 0.0;
  accepted_s = 0.0;
  norm_sum = 0.0;
  sin_dip_sum = 0.0;
}

double FieldGate::norm_ratio(const FieldGateParams& p) const {
  if (!std::isfinite(last_norm_ut) || !(m_ut > 0.0) || !(p.norm_tol > 0.0)) {
    return 0.0;
  }
  return (last_norm_ut - m_ut) / (p.norm_tol * m_ut);
}

double FieldGate::dip_ratio() const {
  if (!std::isfinite(last_norm_ut) || !(sin_hi > sin_lo)) {
    return 0.0;
  }
  return (last_sin_dip - std::sin(dip_rad)) / (0.5 * (sin_hi - sin_lo));
}

bool FieldMovedAtRest::step(const Eigen::Vector3d& field_i, bool at_rest, double dt_s, double lowpass_tau_s,
                            double reference_tau_s, double tol_ut) {
  field_lp = field_lp.allFinite() ? Eigen::Vector3d(field_lp + (dt_s / (lowpass_tau_s + dt_s)) * (field_i - field_lp))
                                  : field_i;
  if (!at_rest) {
    clear();
    return false;
  }
  if (!rest_field.allFinite()) {
    rest_field = field_lp;
  }
  const bool moved = (field_lp - rest_field).norm() > tol_ut;
  if (!moved && reference_tau_s > 0.0) {
    // a slow change is followed, as the gate's reference follows the accepted field: never the
    // moved one (a magnet's field adopted would outlast the magnet)
    rest_field += (dt_s / (reference_tau_s + dt_s)) * (field_lp - rest_field);
  }
  return moved;
}

bool FieldMovedAtRest::hold(bool moved, bool at_rest, bool judged, double tol_ut) {
  if (at_rest) {
    held = moved;
  } else if (held) {
    held = !judged && !((field_lp - rest_field).norm() <= tol_ut);
    if (!held) {
      clear();
    }
  }
  return held;
}

}  // namespace poise
