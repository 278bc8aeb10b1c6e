// Aid sources: the camera (AprilTag) pose, at its capture time (the filter restores the snapshot
// at or before it and replays what came after: selective_ekf.cpp).
//   attitude:  log(q^-1 (x) q_vis) = dth, H = [0 I 0 0 0], q_vis = q_world_cam (x) q_body_cam^-1;
//              the first one (and one after vision_reset_after_rejections gate rejections in a
//              row) resets the attitude to the measurement.
//   position:  p_world_cam = t + R(q) p_body_cam, H = [0 -R [p_body_cam x] 0 I 0]; the first one
//              (and the next after as many rejections) sets the position.
// Both gated by the innovation test at vision_gate_sigma.
#include "aid.h"

#include <Eigen/Eigenvalues>

#include <cmath>

namespace poise::selective_ekf_aids {

VisionMeasurement vision_measurement(const SelectiveEkfParams& p, const VisionPose& v) {
  VisionMeasurement m;
  m.stamp_ns = v.capture_stamp_ns;
  m.q_world_body = (v.q_world_camera.normalized() * p.q_body_camera.conjugate()).normalized();
  m.has_position = v.has_position;
  m.p_world_camera_m = v.p_world_camera_m;
  m.sigma_rad = std::isfinite(v.sigma_rad) && v.sigma_rad > 0.0 ? v.sigma_rad : p.sigma_vision_deg * kRadPerDeg;
  m.sigma_m = std::isfinite(v.sigma_m) && v.sigma_m > 0.0 ? v.sigma_m : p.sigma_vision_m;
  m.has_attitude_covariance = has_attitude_covariance(v) && attitude_covariance_ok(v.attitude_covariance_world);
  m.attitude_covariance_world = m.has_attitude_covariance ? v.attitude_covariance_world
                                                          : Eigen::Matrix3d::Identity() * m.sigma_rad * m.sigma_rad;
  if (m.has_attitude_covariance) {
    m.sigma_rad = std::sqrt(m.attitude_covariance_world.trace() / 3.0);  // its RMS (time-offset estimator)
  }
  return m;
}

bool has_attitude_covariance(const VisionPose& v) { return (v.attitude_covariance_world.array() != 0.0).any(); }

bool attitude_covariance_ok(const Eigen::Matrix3d& c) {
  // symmetric to the rounding of a computed covariance (relative 1e-6)
  if (!c.allFinite() || !((c - c.transpose()).cwiseAbs().maxCoeff() <= 1e-6 * c.cwiseAbs().maxCoeff())) {
    return false;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(c);
  return eig.info() == Eigen::Success && eig.eigenvalues().minCoeff() > 0.0;
}

void aid_vision_attitude(const AidContext& c, const VisionMeasurement& v, SourceStatus& st) {
  SelectiveEkfState& x = c.x;
  const int64_t now = v.stamp_ns;
  const double sr = v.sigma_rad;
  // the measurement's covariance in the body frame of the innovation log(q^-1 (x) q_vis): the
  // world-frame rotation vector turned by the measured attitude
  const Eigen::Matrix3d rv = v.q_world_body.toRotationMatrix();
  const Eigen::Matrix3d r_body = v.has_attitude_covariance
                                     ? Eigen::Matrix3d(rv.transpose() * v.attitude_covariance_world * rv)
                                     : Eigen::Matrix3d(Eigen::Matrix3d::Identity() * sr * sr);
  auto reset_attitude = [&]() {
    x.q_world_body = v.q_world_body;
    for (SelectiveEkf::Mat* pm : {&x.P, &x.P_err}) {
      pm->middleRows<3>(SelectiveEkf::kTh).setZero();
      pm->middleCols<3>(SelectiveEkf::kTh).setZero();
      pm->block<3, 3>(SelectiveEkf::kTh, SelectiveEkf::kTh) = r_body;
    }
    x.ext_accel_error.segment<3>(SelectiveEkf::kTh).setZero();  // the attitude is vision's now
    x.heading_per_offset.setZero();
    x.heading_per_removed_offset.setZero();
    x.offset_left_var = 0.0;
    x.vision_aligned = true;
    x.vision_consecutive_rejects = 0;
    x.last_vision_fused_ns = now;
    x.q_error_fail_since_ns = -1;
    record(st, Decision::kReset, now, c.first_pass);
  };
  // validate: the pose was checked on arrival (update_vision); the first one aligns
  if (!x.vision_aligned) {
    reset_attitude();
    return;
  }
  // innovation
  const Eigen::Quaterniond qa = quat_align_sign(v.q_world_body, x.q_world_body);
  const Eigen::Vector3d innov = quat_log(x.q_world_body.conjugate() * qa);
  Eigen::Matrix<double, 3, SelectiveEkf::kN> h = Eigen::Matrix<double, 3, SelectiveEkf::kN>::Zero();
  h.middleCols<3>(SelectiveEkf::kTh).setIdentity();
  // the pose's own covariance: rows along its principal axes (R = V diag(l) V^T: rows V^T H,
  // innovations V^T y, variances l; exact, and the diagonal R the row-by-row update needs)
  Eigen::Vector3d r_diag = Eigen::Vector3d::Constant(sr * sr);
  Eigen::Vector3d y = innov;
  if (v.has_attitude_covariance) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (r_body + r_body.transpose()));
    h.middleCols<3>(SelectiveEkf::kTh) = eig.eigenvectors().transpose();
    y = eig.eigenvectors().transpose() * innov;
    r_diag = eig.eigenvalues();
  }
  // gate and fuse; status (a reset after too many rejections in a row)
  if (fuse<3>(x, h, y, r_diag, c.p.vision_gate_sigma, true, st)) {
    x.vision_consecutive_rejects = 0;
    x.last_vision_fused_ns = now;
    record(st, Decision::kFused, now, c.first_pass);
  } else if (++x.vision_consecutive_rejects >= c.p.vision_reset_after_rejections) {
    reset_attitude();
  } else {
    record(st, Decision::kRejectedGate, now, c.first_pass);
  }
}

void aid_vision_position(const AidContext& c, const VisionMeasurement& v, SourceStatus& st) {
  SelectiveEkfState& x = c.x;
  const SelectiveEkfParams& p = c.p;
  const int64_t now = v.stamp_ns;
  const double sm = v.sigma_m;
  // validate: a pose with a position; the first one sets the position
  if (!v.has_position) {
    return;
  }
  const Eigen::Matrix3d rot = x.q_world_body.toRotationMatrix();
  if (!x.position_aligned) {
    x.t_m = v.p_world_camera_m - rot * p.p_body_camera_m;
    x.v_mps.setZero();
    for (SelectiveEkf::Mat* pm : {&x.P, &x.P_err}) {
      pm->middleRows<3>(SelectiveEkf::kT).setZero();
      pm->middleCols<3>(SelectiveEkf::kT).setZero();
      pm->block<3, 3>(SelectiveEkf::kT, SelectiveEkf::kT) = Eigen::Matrix3d::Identity() * sm * sm;
    }
    x.position_aligned = true;
    record(st, Decision::kReset, now, c.first_pass);
    return;
  }
  // innovation: H = [0  -R [p_body_cam x]  0  I  0] (the attitude block is zero without a lever arm)
  Eigen::Matrix<double, 3, SelectiveEkf::kN> h = Eigen::Matrix<double, 3, SelectiveEkf::kN>::Zero();
  h.middleCols<3>(SelectiveEkf::kTh) = J_rotate_right_perturbation(x.q_world_body, p.p_body_camera_m);
  h.middleCols<3>(SelectiveEkf::kT).setIdentity();
  const Eigen::Vector3d innov = v.p_world_camera_m - (x.t_m + rot * p.p_body_camera_m);
  // gate and fuse; status (re-anchored on the next measurement after too many rejections)
  if (fuse<3>(x, h, innov, Eigen::Vector3d::Constant(sm * sm), p.vision_gate_sigma, true, st)) {
    x.vision_pos_consecutive_rejects = 0;
    record(st, Decision::kFused, now, c.first_pass);
  } else if (++x.vision_pos_consecutive_rejects >= p.vision_reset_after_rejections) {
    x.position_aligned = false;
    x.vision_pos_consecutive_rejects = 0;
    record(st, Decision::kRejectedGate, now, c.first_pass);
  } else {
    record(st, Decision::kRejectedGate, now, c.first_pass);
  }
}

}  // namespace poise::selective_ekf_aids
