// Aid source: the IMU quaternion (ImuMeasurement::kQuaternion, the paper's): the Gauss-Newton
// attitude from accelerometer and magnetometer, rows log(q^-1 (x) q_imu) = dth, H = [0 I 0 0 0].
// Gated by the magnetometer's selective test (mag_trust.cpp; eqs. 8-10): inflated or dropped
// while untrusted.
#include "aid.h"

namespace poise::selective_ekf_aids {

void aid_imu_quat(const AidContext& c, const ImuInput& in, bool anchored, MagTrust& mag, SourceStatus& st) {
  const int64_t now = in.stamp_ns;
  // validate: Gauss-Newton gave a quaternion (it needs the magnetometer)
  if (!in.has_q_imu) {
    record(st, Decision::kRejectedNoMag, now, c.first_pass);
    return;
  }
  // gate: disturbance angle (8) and quaternion error (9)-(10). The predicted up axis is only as
  // good as the tilt: without a recent vision fix the raw accelerometer is used.
  Eigen::Vector3d up = in.accel;
  if (c.p.up_source == UpSource::kFiltered && anchored) {
    up = c.x.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
  }
  const double theta_q = quat_angle_between(c.x.q_world_body, in.q_imu);  // (9)-(10)
  const bool trusted = mag_trusted(c, mag, in, up, theta_q, anchored);
  const MagStatus& m = mag.status;
  const Decision reject_reason = (m.angle_test_failed || m.norm_test_failed || !m.quat_error_test_failed)
                                     ? Decision::kRejectedDisturbance
                                     : Decision::kRejectedQuatError;
  // innovation
  const Eigen::Quaterniond qm = quat_align_sign(in.q_imu, c.x.q_world_body);
  const Eigen::Vector3d innov = quat_log(c.x.q_world_body.conjugate() * qm);
  const double sig = c.p.sigma_imu_quat_deg * kRadPerDeg;
  double r = sig * sig;
  Eigen::Matrix<double, 3, SelectiveEkf::kN> h = Eigen::Matrix<double, 3, SelectiveEkf::kN>::Zero();
  h.middleCols<3>(SelectiveEkf::kTh).setIdentity();
  // reject (drop): report the innovation the rows would have had, then leave them out
  if (!trusted && c.p.action == ImuQuatAction::kDrop) {
    fuse<3>(c.x, h, innov, Eigen::Vector3d::Constant(r), kReportGateSigma, false, st, true);
    record(st, reject_reason, now, c.first_pass);
    return;
  }
  // fuse (inflated while untrusted)
  if (!trusted) {
    r *= c.p.inflate_factor;
  }
  fuse<3>(c.x, h, innov, Eigen::Vector3d::Constant(r), kReportGateSigma, false, st);
  // status
  record(st, trusted ? Decision::kFused : Decision::kFusedInflated, now, c.first_pass);
}

}  // namespace poise::selective_ekf_aids
