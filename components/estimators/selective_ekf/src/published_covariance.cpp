// The selective EKF's published covariance (issue 31; ESTIMATORS.md "The published covariance"):
// P's attitude block carried to the output, plus the errors the filter does not model. The
// estimate never reads it: P keeps its role in the gains and gates, so the estimate is unchanged.
//
// Correction lags and shares, from P and the attitude's process noise q (rad^2/s): for an attitude
// direction held by corrections against a random walk q, the steady state gives the correction
// time constant tau = P / q (IMU only: the tilt's is accel_lowpass_tau_s by construction of the
// derived sigma_tilt, the heading's about 19 s with the defaults; with vision both are far
// shorter). A measurement of noise density r (rad^2 s) contributes P / r of the correction rate
// 1 / tau, so an error of that measurement that is slower than tau reaches the estimate with the
// share P^2 / (q r) (1 when it is the only correction: the low-passed accelerometer for tilt
// without vision, the magnetometer for heading).
//
// Terms (world frame):
//   P          R P_thth R^T at the output, of the estimate's error covariance P_err (P's gains, a
//              gyro sample the rate's mean over its interval: selective_ekf.h), the delay prediction exp(w d) with the rate's
//              covariance, and the output blend's remaining correction delta delta^T
//   delay      imu_delay_s not known (NaN): d is half a sample, the true delay uniform over none
//              to one sample: (dt^2 / 12) (R w)(R w)^T
//   following  tilt: the accelerometer's disturbance (external acceleration, its errors) that the
//              tilt is still following: the tilt rows' innovation as a world-frame rotation,
//              low-passed over the tilt's lag (what averages out within it is left out, what
//              persists is what the estimate is being pulled by): share^2 i_lp i_lp^T (x, y).
//              With accel_noise_density_mps2_per_sqrt_hz known, instead: the external
//              acceleration's error z (SelectiveEkfState::ext_accel_error, the low-pass's error
//              driven by the measured deviation d from it, through P's gains): its tilt part
//              (R z_th) squared and low-passed over the tilt's lag (x, y)
//   scale      tilt and heading: a gyro scale error s_i of body axis i (each its own, independent,
//              gyro_scale_error each) turns the estimate by s_i times that axis' rotation the
//              corrections have not caught up with: its world-frame increments R e_i w_i dt
//              high-passed over each lag (X_i' = R e_i w_i - X_i / tau; x, y over the tilt's lag,
//              z over the heading's), s^2 w_i w_i^T with w_i = (X_i,x, X_i,y, X_i,z + g LP(X_i,y))
//              (the heading's pull through the dip, below)
//   field      heading: the disturbance of the fields the gate accepted, its norm deviation dn and
//              dip deviation dv = m (dip - dip_ref) low-passed over the heading's lag; the part
//              across the horizontal field, which turns the heading, is taken as large as those
//              two: share^2 (dn^2 + dv^2) / 2 / (m cos dip)^2
//   hard_iron  heading: the removed hard-iron offset's estimate's error (covariance P_b, the
//              estimate's error_covariance(): its comparisons' noise as it is, not the gains'
//              covariance(), session 23) in the readings corrected: s_r^T P_b s_r, s_r the
//              heading row's response to it through
//              its own gains (SelectiveEkfState::heading_per_removed_offset, as "offset" below)
//   offset     heading: an offset the hard-iron estimate holds (converged) but does not remove
//              (|b| <= min_applied_ut, or not consistent; significant or not): the
//              heading error it put into the estimate is s . b, s the heading row's response to
//              an offset left in its readings through its own gains
//              (SelectiveEkfState::heading_per_offset: the averaging over the rotation, the
//              gyro-only stretches, other rows' corrections), b ~ N(b_hat, P_b):
//              (s . b_hat)^2 + s^T P_b s (unremoved_offset_var; the mean part only while the
//              estimate is consistent, i.e. a body offset's). When the estimate reopens (the
//              offset changed) both terms move to offset_left_var, which the rows correct away as
//              they do the heading error, and s, s_r count the new offset's readings from zero
//   dip        heading: the unmodelled tilt terms' error through the dip, g = -share tan(dip)
//              times the error about north low-passed over the heading's lag (attitude_covariance;
//              P's own tilt error reaches the heading through the row)
//   unknown    heading: pi^2 / 3 (a heading uniform over +-180 deg) while heading_unknown(): a
//              field reference still learnt or provisional (field_verify_s), or a heading started
//              on a gated field; nothing bounds the heading then (a start next to a magnet)
// The gyro's white noise and bias random walk between corrections, the heading's growth while the
// magnetometer is gated (and its fall when it is trusted again) are P's own; so are the gyro noise
// and bias error seen through the accelerometer low-pass (its error is the state e,
// aid_accel_tilt.cpp) and P's tilt error through the dip (aid_mag_heading.cpp).
#include "aid.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace poise {
namespace aids = selective_ekf_aids;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// dt / (tau + dt): the low-pass gain over one step (0 for an infinite tau).
double lowpass_gain(double dt_s, double tau_s) {
  return std::isfinite(tau_s) ? dt_s / (std::max(tau_s, 0.0) + dt_s) : 0.0;
}

/// The attitude's process noise density in P's model, rad^2/s, what the corrections hold the
/// attitude against: the walk, the gyro's white noise integrated over the sample interval, and
/// the rate model's path inside an interval that the gyro row does not see (q h^3 / 12 per
/// interval, predict_to). The gains' correction time constant is P / this: without the last
/// term (2 rad/s^2/sqrt(Hz), 4.1e-6 rad^2/s at 285.7 Hz, as large as the walk) the lags were
/// taken about 1.4 times too long at 285.7 Hz and 9 times at 40.8 Hz.
double attitude_process_noise(const SelectiveEkfParams& p, double dt_s) {
  const double h = std::max(dt_s, 0.0);
  return p.sigma_attitude_walk * p.sigma_attitude_walk + p.sigma_gyro_rps * p.sigma_gyro_rps * h +
         p.sigma_angular_accel * p.sigma_angular_accel * h * h / 12.0;
}

}  // namespace

double SelectiveEkf::heading_lag_s() const {
  const Eigen::Vector3d u = x_.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
  const double p_h = u.dot(x_.P.block<3, 3>(kTh, kTh) * u);
  const double q = attitude_process_noise(p_, x_.unmodelled.last_dt_s);
  return q > 0.0 ? p_h / q : kInf;
}

bool SelectiveEkf::vision_anchors() const {
  return x_.last_vision_fused_ns >= 0 &&
         x_.stamp_ns - x_.last_vision_fused_ns <= aids::seconds_to_ns(p_.vision_anchor_s);
}

HeadingStatus SelectiveEkf::heading_status() const {
  if (!initialized_) {
    return HeadingStatus::kNoReference;
  }
  if (vision_anchors()) {
    return HeadingStatus::kVerified;
  }
  const bool split = p_.imu_measurement == ImuMeasurement::kSplit;
  const SourceStatus& heading = status(split ? SelectiveEkfAid::kMagHeading : SelectiveEkfAid::kImuQuat);
  if (heading.last == Decision::kNone || heading.last == Decision::kRejectedNoMag) {
    return HeadingStatus::kNoReference;
  }
  const bool reference = split ? x_.field_gate.learnt && x_.field_gate.verified && !heading_unknown()
                               : mag_.reference_ready;
  return reference && heading.last == Decision::kFused ? HeadingStatus::kVerified : HeadingStatus::kUnverified;
}

bool SelectiveEkf::heading_unknown() const {
  if (!initialized_ || p_.imu_measurement != ImuMeasurement::kSplit || !(gp_.verify_s > 0.0) || vision_anchors()) {
    return false;
  }
  const SourceStatus& heading = status(SelectiveEkfAid::kMagHeading);
  if (heading.last == Decision::kNone || heading.last == Decision::kRejectedNoMag) {
    return false;  // no field yet (6-axis: the gyro's heading, P's own variance)
  }
  return !x_.field_gate.verified || !x_.heading_anchored;
}

void SelectiveEkf::track_unmodelled(const ImuInput& in, bool aided, double aiding_dt_s) {
  SelectiveEkfUnmodelled& u = x_.unmodelled;
  if (!(in.dt_s > 0.0)) {
    u = SelectiveEkfUnmodelled{};
    return;
  }
  u.last_dt_s = in.dt_s;
  const double q = attitude_process_noise(p_, in.dt_s);
  const Eigen::Matrix3d r = x_.q_world_body.toRotationMatrix();
  const Eigen::Matrix3d p_world = r * x_.P.block<3, 3>(kTh, kTh) * r.transpose();
  const double tau_tilt = q > 0.0 ? 0.5 * (p_world(0, 0) + p_world(1, 1)) / q : kInf;
  const double tau_heading = heading_lag_s();
  // column i: body axis i's rotation increment in the world frame
  const Eigen::Matrix3d turn = r * (x_.w_rps * in.dt_s).asDiagonal();
  u.rotation_tilt = (1.0 - lowpass_gain(in.dt_s, tau_tilt)) * (u.rotation_tilt + turn);
  u.rotation_heading = (1.0 - lowpass_gain(in.dt_s, tau_heading)) * (u.rotation_heading + turn.row(2).transpose());
  if (p_.imu_measurement == ImuMeasurement::kSplit) {
    const SourceStatus& tilt = status(SelectiveEkfAid::kAccelTilt);
    if (aided && tilt.last_stamp_ns == in.stamp_ns) {
      // the rows are e_i . (z_up x u) = e_i . dth with e_1, e_2 across u (aid_accel_tilt.cpp)
      const Eigen::Vector3d up = x_.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
      const Eigen::Vector3d a = std::abs(up.x()) < 0.6 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
      const Eigen::Vector3d e1 = up.cross(a).normalized();
      const Eigen::Vector3d e2 = up.cross(e1);
      const Eigen::Vector3d innov_world = r * (e1 * tilt.innovation.x() + e2 * tilt.innovation.y());
      u.tilt_innovation_lp += lowpass_gain(aiding_dt_s, tau_tilt) * (innov_world - u.tilt_innovation_lp);
      if (aids::accel_noise_known(p_)) {
        const Eigen::Vector2d z = (r * x_.ext_accel_error.segment<3>(kTh)).head<2>();
        u.ext_accel_power += lowpass_gain(aiding_dt_s, tau_tilt) * (z * z.transpose() - u.ext_accel_power);
      }
    }
  }
  // the same tilt errors as the heading's corrections average them (the dip term below)
  const double kh = lowpass_gain(in.dt_s, tau_heading);
  u.rotation_tilt_at_heading += kh * (u.rotation_tilt.row(1).transpose() - u.rotation_tilt_at_heading);
  u.tilt_innovation_at_heading += kh * (u.tilt_innovation_lp.y() - u.tilt_innovation_at_heading);
  if (p_.imu_measurement == ImuMeasurement::kSplit && aids::accel_noise_known(p_)) {
    const double z_north = (r * x_.ext_accel_error.segment<3>(kTh)).y();
    u.ext_accel_at_heading += kh * (z_north - u.ext_accel_at_heading);
  }
  const SourceStatus& heading = status(SelectiveEkfAid::kMagHeading);
  const FieldGate& g = x_.field_gate;
  if (aided && heading.last == Decision::kFused && heading.last_stamp_ns == in.stamp_ns && g.learnt &&
      g.m_ut > 0.0 && std::isfinite(g.last_norm_ut)) {
    const double k = lowpass_gain(aiding_dt_s, tau_heading);
    const double dip = std::asin(std::clamp(g.last_sin_dip, -1.0, 1.0));
    u.field_dn_lp += k * (g.last_norm_ut - g.m_ut - u.field_dn_lp);
    u.field_dv_lp += k * (g.m_ut * (dip - g.dip_rad) - u.field_dv_lp);
  }
}

/// The estimate's own error covariance at the output (world rotation-vector axes): P_err taken
/// through the delay prediction, the start's tilt bound while it is not settled, and the output
/// blend's remaining correction.
Eigen::Matrix3d SelectiveEkf::output_error_covariance() const {
  // P at the output: th_out = Exp(w d)^T th + J_r(w d) d w (the delay prediction)
  const double d = static_cast<double>(current_delay_ns()) * aids::kNsToS;
  const Eigen::Vector3d wd = x_.w_rps * d;
  const Eigen::Matrix3d a = quat_exp(wd).toRotationMatrix().transpose();
  const Eigen::Matrix3d b = so3_right_jacobian(wd) * d;
  // (the estimate's error covariance: P's gains, the process noise of a gyro sample that is the
  // rate's mean over its interval; SelectiveEkfState::P_err)
  // (a start at rest whose first sample's external acceleration is not settled: its tilt bound,
  // turned from the low-pass's frame to the body's, settle_start)
  Eigen::Matrix3d p_tt = x_.P_err.block<3, 3>(kTh, kTh);
  if (x_.pre.start_pending) {
    const Eigen::Matrix3d r_ib = x_.pre.q_ib.toRotationMatrix();
    p_tt += r_ib.transpose() * x_.pre.start_tilt_bound * r_ib;
  }
  const Eigen::Matrix3d p_tw = x_.P_err.block<3, 3>(kTh, kW);
  const Eigen::Matrix3d p_ww = x_.P_err.block<3, 3>(kW, kW);
  const Eigen::Matrix3d body = a * p_tt * a.transpose() + a * p_tw * b.transpose() +
                               b * p_tw.transpose() * a.transpose() + b * p_ww * b.transpose();
  const Eigen::Quaterniond q_state = state_output();
  const Eigen::Matrix3d r = q_state.toRotationMatrix();
  Eigen::Matrix3d cov = r * body * r.transpose();
  // the output blend's remaining correction (world frame): q_out = exp(delta) q_state
  const Eigen::Vector3d delta = quat_log(quat_align_sign(q_world_body(), q_state) * q_state.conjugate());
  cov += delta * delta.transpose();
  return cov;
}

/// The heading's magnetometer row variance density (rad^2 s) of the last sample, as fused
/// (inflated while untrusted); infinite when the last sample was not fused.
double SelectiveEkf::heading_row_density() const {
  const SourceStatus& heading = status(SelectiveEkfAid::kMagHeading);
  if (heading.last != Decision::kFused && heading.last != Decision::kFusedInflated) {
    return kInf;
  }
  return p_.sigma_heading_rad_sqrt_s * p_.sigma_heading_rad_sqrt_s *
         aids::heading_noise_factor(p_, x_.field_gate, gp_) *
         (heading.last == Decision::kFusedInflated ? p_.inflate_factor : 1.0);
}

double SelectiveEkf::unremoved_offset_var() const {
  // an estimate converged (every axis' sigma below converged_sigma_ut) and not removed, whatever
  // its size and significance: b ~ N(b_hat, P_b) is what the filter knows of the offset in its
  // readings (not converged, P_b is still the prior's: nothing known; removed, hard_iron's term)
  const HardIronEstimator& hi = x_.hard_iron;
  if (p_.imu_measurement != ImuMeasurement::kSplit || !p_.hard_iron || !hi.converged() || hi.applied()) {
    return 0.0;
  }
  // b_hat is a body offset's only while removing it makes |m| more constant over the rotation
  // (consistent); otherwise it fits a field that varies in space (a magnet near the sensor, not
  // on it: the field term's), and of a body offset only P_b is known
  const Eigen::Vector3d& s = x_.heading_per_offset;
  const double mean = hi.report().consistent ? s.dot(hi.offset_ut()) : 0.0;
  return mean * mean + s.dot(hi.error_covariance() * s);
}

double SelectiveEkf::removed_offset_var() const {
  const HardIronEstimator& hi = x_.hard_iron;
  if (p_.imu_measurement != ImuMeasurement::kSplit || !p_.hard_iron || !hi.converged()) {
    return 0.0;
  }
  const Eigen::Vector3d& s = x_.heading_per_removed_offset;
  return s.dot(hi.error_covariance() * s);
}

Eigen::Matrix3d SelectiveEkf::attitude_covariance() const {
  const SelectiveEkfUnmodelled& u = x_.unmodelled;
  const Eigen::Matrix3d r = state_output().toRotationMatrix();
  Eigen::Matrix3d cov = output_error_covariance();

  if (std::isnan(p_.imu_delay_s)) {
    // the delay not known: predicted over half a sample, the true one taken as uniform over none
    // to one sample (variance dt^2 / 12); its error turns the output about the rate axis
    const Eigen::Vector3d w_world = r * x_.w_rps;
    cov += (u.last_dt_s * u.last_dt_s / 12.0) * (w_world * w_world.transpose());
  }
  if (heading_unknown()) {
    cov(2, 2) += kUnknownHeadingVarRad2;
  }
  const double q = attitude_process_noise(p_, u.last_dt_s);
  if (!(q > 0.0)) {
    return cov;
  }
  // the lags and shares are the gains', P's
  const Eigen::Matrix3d p_world = r * x_.P.block<3, 3>(kTh, kTh) * r.transpose();
  const double p_tilt = 0.5 * (p_world(0, 0) + p_world(1, 1));
  const double p_heading = p_world(2, 2);
  const bool split = p_.imu_measurement == ImuMeasurement::kSplit;
  const FieldGate& fg = x_.field_gate;
  const double r_heading = split ? heading_row_density() : kInf;
  const double cos_dip = std::cos(fg.dip_rad);
  const bool mag_row = std::isfinite(r_heading) && fg.learnt && cos_dip > 1e-3;
  // the magnetometer's share of the heading's correction
  const double share_heading = mag_row ? std::min(1.0, p_heading * p_heading / (q * r_heading)) : 0.0;
  // heading: the tilt's error through the dip. The row's innovation is
  //   dpsi = dth_z + tan(dip) dth_n
  // with dth_n the world-frame error about magnetic north (+y, the reference's horizontal
  // direction). The row's H has both terms and considers the tilt (aid_mag_heading.cpp), so P's
  // own tilt error reaches P's heading. A tilt error P does not hold pulls the heading where the
  // row's two terms cancel, e_z = g e_y with g = -share tan(dip), as fast as the heading's
  // corrections go: the heading takes g times that error low-passed over its lag (the *_at_heading
  // realizations), not the error of the moment (session 22: a tilt error that comes and goes
  // within the tilt's 3 s lag does not reach a heading whose lag is 17 s).
  const double g = mag_row ? -share_heading * std::tan(fg.dip_rad) : 0.0;
  Eigen::Matrix3d slow = Eigen::Matrix3d::Zero();
  if (p_.gyro_scale_error > 0.0) {
    // gyro scale error, each axis' its own (independent, gyro_scale_error each): s_i times axis
    // i's rotation away from the attitude low-passed over each lag; the heading's is its own lag's
    // plus the tilt's pulled through the dip
    const double s2 = p_.gyro_scale_error * p_.gyro_scale_error;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d w(u.rotation_tilt(0, i), u.rotation_tilt(1, i),
                              u.rotation_heading(i) + g * u.rotation_tilt_at_heading(i));
      slow += s2 * w * w.transpose();
    }
  }
  if (!split) {
    return cov + slow;
  }
  slow += tilt_following(q, p_tilt, g);
  // heading: the accepted field's disturbance, by the magnetometer's share of the heading's correction
  if (mag_row && fg.m_ut > 0.0) {
    const double share2 = share_heading * share_heading;
    const double mh = fg.m_ut * cos_dip;
    const double power = 0.5 * (u.field_dn_lp * u.field_dn_lp + u.field_dv_lp * u.field_dv_lp);
    cov(2, 2) += share2 * power / (mh * mh);
  }
  cov(2, 2) += unremoved_offset_var() + removed_offset_var() + x_.offset_left_var;
  return cov + slow;
}

/// The tilt's error from the accelerometer's disturbance (world x, y) and the heading's through the
/// dip (g, the attitude_covariance comment): its tilt realization v and the heading's g v_y
/// low-passed over the heading's lag, w = (v_x, v_y, g LP(v_y)), as w w^T.
Eigen::Matrix3d SelectiveEkf::tilt_following(double q, double p_tilt, double g) const {
  const SelectiveEkfUnmodelled& u = x_.unmodelled;
  Eigen::Matrix3d out = Eigen::Matrix3d::Zero();
  if (aids::accel_noise_known(p_)) {
    // the accelerometer's noise known (the tilt rows carry none in P_err): the external
    // acceleration's error through the filter's own gains (ext_accel_error), its power over the
    // tilt's lag; it holds what "following" below stands for. A power, not one realization: the
    // heading's part is g times the realization low-passed over the heading's lag, taken as
    // correlated with the tilt's (B = I + k e_z e_y^T, k^2 P_yy = (g LP(z_y))^2)
    out.topLeftCorner<2, 2>() = u.ext_accel_power;
    const double pyy = u.ext_accel_power(1, 1);
    if (pyy > 0.0) {
      Eigen::Matrix3d b = Eigen::Matrix3d::Identity();
      b(2, 1) = g * std::abs(u.ext_accel_at_heading) / std::sqrt(pyy);
      out = b * out * b.transpose();
    }
    return out;
  }
  // tilt: the low-passed accelerometer's own errors, by its share of the tilt's correction
  const double tilt_sigma = std::isnan(p_.sigma_tilt_rad_sqrt_s)
                                ? p_.accel_lowpass_tau_s * std::sqrt(q)
                                : p_.sigma_tilt_rad_sqrt_s;
  const double r_tilt = tilt_sigma * tilt_sigma;
  if (r_tilt > 0.0) {
    const double share = std::min(1.0, p_tilt * p_tilt / (q * r_tilt));
    const Eigen::Vector3d w = share * Eigen::Vector3d(u.tilt_innovation_lp.x(), u.tilt_innovation_lp.y(),
                                                      g * u.tilt_innovation_at_heading);
    out = w * w.transpose();
  }
  return out;
}

}  // namespace poise
