// The magnetometer's selective test (paper 002 eqs. 8-10), shared by the two magnetometer aids
// (aid_mag_heading.cpp, aid_imu_quat.cpp): the disturbance angle (8) between m and the up vector
// against 90 deg + dip (split mode: the field gate of poise/core/field_gate.h, with |m|), and the
// quaternion error (9)-(10). Either failing marks the magnetometer untrusted, for
// untrusted_hold_s after the last failure.
#include "aid.h"

#include <cmath>

namespace poise::selective_ekf_aids {

bool mag_trusted(const AidContext& c, MagTrust& mag, const ImuInput& in, const Eigen::Vector3d& up,
                 double theta_q, bool anchored) {
  const SelectiveEkfParams& p = c.p;
  SelectiveEkfState& x = c.x;
  MagStatus& m = mag.status;
  const int64_t now = in.stamp_ns;
  const double theta_m = angle_between_vectors(in.mag, up);  // (8)
  m.disturbance_angle_deg = theta_m * kDegPerRad;
  m.quat_error_deg = theta_q * kDegPerRad;
  // kSplit measures the dip against the filtered tilt (accurate without vision) and |m| with the
  // parallel KF's field gate (learnt, following, re-acquired reference); its quaternion-error test
  // compares with a heading that only vision anchors (see the notation).
  const bool split = p.imu_measurement == ImuMeasurement::kSplit;
  bool field_disturbed = false;
  if (split) {
    FieldGate& g = x.field_gate;
    const FieldVerdict v = g.step(mag.gate, in.mag, up, in.dt_s);
    g.tick(mag.gate, in.dt_s);
    mag.verdict = v;
    field_disturbed = v == FieldVerdict::kGated;
    m.reference_ready = g.learnt;
    m.dip_deg = g.dip_rad * kDegPerRad;
    m.reference_angle_deg = 90.0 + m.dip_deg;
    m.norm_ratio = g.m_ut > 0.0 ? in.mag.norm() / g.m_ut : 1.0;
    m.norm_test_failed = field_disturbed && std::abs(g.norm_ratio(mag.gate)) > 1.0;
    m.angle_test_failed = field_disturbed && (g.last_sin_dip < g.sin_lo || g.last_sin_dip > g.sin_hi);
  } else {
    m.angle_test_failed = m.reference_ready &&
                          std::abs(theta_m - mag.ref_angle_rad) > p.disturbance_angle_threshold_deg * kRadPerDeg;
    m.norm_test_failed = false;
    if (p.mag_norm_test && mag.ref_norm_ut > 0.0) {
      m.norm_ratio = in.mag.norm() / mag.ref_norm_ut;
      m.norm_test_failed = std::abs(m.norm_ratio - 1.0) > p.mag_norm_threshold;
    }
    field_disturbed = m.angle_test_failed || m.norm_test_failed;
  }
  bool q_fail = p.quat_error_test && (!split || anchored) && theta_q > p.quat_error_threshold_deg * kRadPerDeg;
  if (q_fail) {
    if (x.q_error_fail_since_ns < 0) {
      x.q_error_fail_since_ns = now;
    }
    if (!anchored && now - x.q_error_fail_since_ns > seconds_to_ns(p.q_error_lockout_s)) {
      q_fail = false;  // lock-out release: the prediction, not the measurement, may have drifted
    }
  } else {
    x.q_error_fail_since_ns = -1;
  }
  m.quat_error_test_failed = q_fail;
  const bool disturbed = field_disturbed || q_fail;
  if (p.gating_enabled && disturbed) {
    x.untrusted_until_ns = now + seconds_to_ns(p.untrusted_hold_s);
  }
  // untrusted while a test fails, and for untrusted_hold_s after the last failure
  const bool trusted = !p.gating_enabled || (!disturbed && (x.untrusted_until_ns < 0 || now >= x.untrusted_until_ns));
  m.trusted = trusted;
  if (!trusted && c.first_pass) {
    ++m.untrusted_samples;
  }
  return trusted;
}

}  // namespace poise::selective_ekf_aids
