// Aid source: the heading from the magnetometer (ImuMeasurement::kSplit). dpsi is the rotation
// about world up taking the horizontal part of R(q) m onto magnetic north (+y ENU); a world-frame
// rotation dpsi e_z is the body-frame rotation dpsi u, and a tilted estimate turns the field's
// horizontal projection by tan(dip) times its tilt error about north, so one row
// dpsi = (u + tan(dip) R^T e_y) . dth, with the tilt considered (its gain zeroed: a disturbed field
// never tilts the estimate; Joseph form). Variance: the spectral density sigma_heading^2 / dt, raised as the field nears the gate's tolerances. Gated
// by the magnetometer's selective test (mag_trust.cpp): inflated or dropped while untrusted.
#include "aid.h"

#include <cmath>

namespace poise::selective_ekf_aids {

double heading_noise_factor(const SelectiveEkfParams& p, const FieldGate& gate, const FieldGateParams& gp) {
  if (!(p.heading_disturbance_weight > 0.0) || !std::isfinite(gate.last_norm_ut)) {
    return 1.0;
  }
  const double rn = gate.norm_ratio(gp);
  const double rd = gate.dip_ratio();
  return 1.0 + p.heading_disturbance_weight * (rn * rn + rd * rd);
}

namespace {
/// d dpsi / d m_body of the heading row's innovation at the field mw = R m (world, horizontal
/// part horiz): the heading error a body-fixed offset in the reading puts in per uT, rad/uT.
Eigen::Vector3d offset_heading_sensitivity(const Eigen::Quaterniond& q_world_body, const Eigen::Vector3d& mw,
                                          double horiz) {
  return q_world_body.conjugate() * (Eigen::Vector3d(mw.y(), -mw.x(), 0.0) / (horiz * horiz));
}
}  // namespace

void restart_heading(const AidContext& c, const Eigen::Vector3d& up, double dpsi) {
  SelectiveEkfState& x = c.x;
  // world-frame turn about e_z = body-frame turn about up: q exp(dpsi up) = exp(dpsi e_z) q
  x.q_world_body = (x.q_world_body * quat_exp(dpsi * up)).normalized();
  // P <- T P T^T with T the identity but (I - up up^T) on the attitude block: the heading
  // direction's variance and correlations dropped (positive semi-definite kept), then its start
  SelectiveEkf::Mat t = SelectiveEkf::Mat::Identity();
  t.block<3, 3>(SelectiveEkf::kTh, SelectiveEkf::kTh) -= up * up.transpose();
  const double s0 = c.p.init_sigma_attitude_deg * kRadPerDeg;
  for (SelectiveEkf::Mat* pm : {&x.P, &x.P_err}) {
    *pm = t * *pm * t.transpose();
    pm->block<3, 3>(SelectiveEkf::kTh, SelectiveEkf::kTh) += s0 * s0 * up * up.transpose();
  }
  // the published covariance's field and rotation terms belonged to the old heading
  x.unmodelled.field_dn_lp = 0.0;
  x.unmodelled.field_dv_lp = 0.0;
  x.unmodelled.rotation_heading.setZero();
  x.unmodelled.rotation_tilt_at_heading.setZero();
  x.unmodelled.tilt_innovation_at_heading = 0.0;
  x.unmodelled.ext_accel_at_heading = 0.0;
  x.heading_per_offset.setZero();  // (the caller: the new heading's reading)
  x.heading_per_removed_offset.setZero();
  x.offset_left_var = 0.0;
}

void refuse_field(const AidContext& c, const ImuInput& in, MagTrust& mag, SourceStatus& st) {
  // Not the Earth's field, whatever the gate would say of it at this orientation: it moved while
  // the sensor was still (a magnet attached or brought near; the heading at rest needs no field),
  // or it carries a body-fixed offset the estimate cannot remove yet (an offset across the
  // horizontal field barely moves |m| or the dip, and one that reverses it can pass both). Not
  // fused, and not the gate's: the field did not change for good, so its clocks (reacquire,
  // forced use) do not run; the reference's window still advances.
  c.x.field_gate.tick(mag.gate, in.dt_s);
  MagStatus& m = mag.status;
  m.trusted = false;
  m.angle_test_failed = false;
  m.norm_test_failed = false;
  m.quat_error_test_failed = false;
  if (c.first_pass) {
    ++m.untrusted_samples;
  }
  st.innovation.setZero();
  st.innovation_variance.setZero();
  st.test_ratio = 0.0;
  record(st, Decision::kRejectedDisturbance, in.stamp_ns, c.first_pass);
}

void aid_mag_heading(const AidContext& c, const ImuInput& in, bool anchored, MagTrust& mag, SourceStatus& st) {
  const int64_t now = in.stamp_ns;
  // validate: a magnetometer sample, an interval for the density, a field that is not vertical
  if (!in.has_mag || !(in.dt_s > 0.0)) {
    record(st, Decision::kRejectedNoMag, now, c.first_pass);
    return;
  }
  // refused before the gate (a magnet attached: field_offsets)
  // (the selective part: not with gating_enabled false)
  const bool refusing = c.p.gating_enabled && c.x.heading_checked;
  mag.status.offset_pending = refusing && c.x.mag_offset_pending;
  mag.status.moved_at_rest = refusing && c.x.mag_moved_at_rest;
  if (mag.status.offset_pending || mag.status.moved_at_rest) {
    refuse_field(c, in, mag, st);
    return;
  }
  const Eigen::Vector3d mw = c.x.q_world_body * in.mag;
  const double horiz = std::hypot(mw.x(), mw.y());
  if (!(horiz > 1e-3 * in.mag.norm())) {
    record(st, Decision::kRejectedBadInput, now, c.first_pass);  // field vertical: no heading
    return;
  }
  // innovation
  const double dpsi = wrap_angle(0.5 * kPi - std::atan2(mw.y(), mw.x()));
  const Eigen::Vector3d u = c.x.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
  // gate: the selective test, against the filter's up axis and |dpsi| as the quaternion error
  const bool trusted = mag_trusted(c, mag, in, u, std::abs(dpsi), anchored);
  // cold start (field_verify_s): the heading restarts on a relearnt reference's field, and after
  // a start on a field the gate gated, on the first one it accepts; vision, when it anchors the
  // attitude, holds the heading instead
  const FieldVerdict v = mag.verdict;
  if (!c.x.heading_checked) {
    c.x.heading_checked = true;
    c.x.heading_anchored = v != FieldVerdict::kGated || !(mag.gate.verify_s > 0.0);
  }
  if (v == FieldVerdict::kRelearnt || (v == FieldVerdict::kAccepted && !c.x.heading_anchored)) {
    c.x.heading_anchored = true;
    if (!anchored) {
      const Eigen::Vector3d started = offset_heading_sensitivity(c.x.q_world_body, mw, horiz);
      restart_heading(c, u, dpsi);
      // the new heading is this reading's, whole
      (c.x.mag_corrected ? c.x.heading_per_removed_offset : c.x.heading_per_offset) = started;
      record(st, Decision::kReset, now, c.first_pass);
      return;
    }
  }
  // the row: dpsi = e_z . th_w + tan(dip) e_n . th_w (th_w = R dth the world-frame error, e_n
  // magnetic north = +y): a tilted estimate turns the field's horizontal projection, so the tilt's
  // error about north reaches the heading innovation through the dip
  const double tan_dip = c.x.field_gate.learnt ? std::tan(c.x.field_gate.dip_rad) : 0.0;
  const Eigen::Vector3d north_body = c.x.q_world_body.conjugate() * Eigen::Vector3d::UnitY();
  Eigen::Matrix<double, 1, SelectiveEkf::kN> h = Eigen::Matrix<double, 1, SelectiveEkf::kN>::Zero();
  h.block<1, 3>(0, SelectiveEkf::kTh) = (u + tan_dip * north_body).transpose();
  double r = c.p.sigma_heading_rad_sqrt_s * c.p.sigma_heading_rad_sqrt_s / in.dt_s;
  r *= heading_noise_factor(c.p, c.x.field_gate, mag.gate);
  const Eigen::Matrix<double, 1, 1> innov(dpsi);
  // reject (drop): report the innovation the row would have had, then leave it out
  if (!trusted && c.p.action == ImuQuatAction::kDrop) {
    fuse<1>(c.x, h, innov, Eigen::Matrix<double, 1, 1>(r), kReportGateSigma, false, st, true);
    const MagStatus& m = mag.status;
    record(st, m.quat_error_test_failed && !m.angle_test_failed && !m.norm_test_failed
                   ? Decision::kRejectedQuatError
                   : Decision::kRejectedDisturbance,
           now, c.first_pass);
    return;
  }
  // fuse (inflated while untrusted)
  if (!trusted) {
    r *= c.p.inflate_factor;
  }
  // the tilt is a consider state of this row (a disturbed field never costs tilt): its gain is
  // zeroed, the heading's kept (the attitude block's gain projected on u), P keeps the tilt's
  // uncertainty and its correlation with the heading (Joseph form)
  SelectiveEkf::Mat keep = SelectiveEkf::Mat::Identity();
  keep.block<3, 3>(SelectiveEkf::kTh, SelectiveEkf::kTh) = u * u.transpose();
  keep.block<3, 3>(SelectiveEkf::kB, SelectiveEkf::kB) = u * u.transpose();
  keep.block<3, 3>(SelectiveEkf::kE, SelectiveEkf::kE).setZero();
  const Eigen::Matrix<double, 1, 1> rr(r);
  // the row's heading gain u^T K (P before the row): an offset left in the reading moves dpsi by
  // a . (R off), a = (m_n, -m_e, 0) / horiz^2, and the heading by the gain times that
  // (SelectiveEkfState::heading_per_offset; the row's own share taken back in the update)
  const Eigen::Matrix<double, SelectiveEkf::kN, 1> ph = c.x.P * h.transpose();
  const double k_heading = u.dot(ph.segment<3>(SelectiveEkf::kTh)) / (h.dot(ph) + r);
  const Eigen::Vector3d drive = offset_heading_sensitivity(c.x.q_world_body, mw, horiz);
  st.innovation_variance.setZero();
  st.innovation_variance.head<1>() = fuse_considered<1>(c.x, h, innov, rr, rr, keep);
  (c.x.mag_corrected ? c.x.heading_per_removed_offset : c.x.heading_per_offset) += k_heading * drive;
  st.innovation.setZero();
  st.innovation[0] = dpsi;
  st.test_ratio = dpsi * dpsi / (kReportGateSigma * kReportGateSigma * st.innovation_variance[0]);
  // status
  record(st, trusted ? Decision::kFused : Decision::kFusedInflated, now, c.first_pass);
}

}  // namespace poise::selective_ekf_aids
