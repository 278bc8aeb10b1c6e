// The selective EKF's outputs in the shapes every node maps 1:1 (per-source report, world-frame
// covariances, the vision input of a camera pose). Pure functions of the filter's public state,
// apart from its mathematics in selective_ekf.cpp.
#include "poise/selective_ekf/selective_ekf.h"

#include "aid.h"

#include <Eigen/Eigenvalues>

#include <cmath>

namespace poise {
namespace {

/// The decision of one aid's SourceStatus in the shared shape.
SourceReport from_status(const SelectiveEkf& ekf, SelectiveEkfAid aid) {
  const SourceStatus& st = ekf.status(aid);
  SourceReport r(source_of(aid));
  r.fused_count = st.fused;
  r.rejected_count = st.rejected;
  r.last_fused_stamp_ns = st.last_fused_stamp_ns;
  r.innovation = st.innovation;
  r.innovation_variance = st.innovation_variance;
  r.test_ratio = st.test_ratio;
  switch (st.last) {
    case Decision::kNone: r.decision = SourceDecision::kNotAvailable; r.reason = "no_sample"; break;
    case Decision::kFused: r.decision = SourceDecision::kFused; break;
    case Decision::kFusedInflated: r.decision = SourceDecision::kFused; r.reason = "inflated"; break;
    case Decision::kReset: r.decision = SourceDecision::kFused; r.reason = "reset"; break;
    case Decision::kRejectedDisturbance: r.decision = SourceDecision::kRejected; r.reason = "disturbance"; break;
    case Decision::kRejectedQuatError: r.decision = SourceDecision::kRejected; r.reason = "quat_error"; break;
    case Decision::kRejectedNoMag: r.decision = SourceDecision::kNotAvailable; r.reason = "no_mag"; break;
    case Decision::kRejectedGate: r.decision = SourceDecision::kRejected; r.reason = "gate"; break;
    case Decision::kRejectedBadInput: r.decision = SourceDecision::kRejected; r.reason = "bad_input"; break;
    case Decision::kRejectedTooOld: r.decision = SourceDecision::kRejected; r.reason = "too_old"; break;
    case Decision::kRejectedStateReset: r.decision = SourceDecision::kRejected; r.reason = kStateResetReason; break;
    case Decision::kCount: break;
  }
  if (r.decision == SourceDecision::kNotAvailable) {
    r.innovation.resize(0);
    r.innovation_variance.resize(0);
    r.test_ratio = 0.0;
  }
  return r;
}

}  // namespace

SourceReports selective_ekf_sources(const SelectiveEkf& ekf) {
  const SelectiveEkfParams& p = ekf.params();
  const int64_t now = ekf.state().stamp_ns;
  const auto recent_ns = static_cast<int64_t>(std::llround(p.vision_anchor_s * 1e9));
  SourceReports out;
  out.reserve(8);
  out.push_back(from_status(ekf, SelectiveEkfAid::kGyro));
  out.push_back(from_status(ekf, SelectiveEkfAid::kImuQuat));
  // The magnetometer's row: the heading (kSplit) or the IMU quaternion (kQuaternion).
  const bool split = p.imu_measurement == ImuMeasurement::kSplit;
  const SourceStatus& quat = ekf.status(split ? SelectiveEkfAid::kMagHeading : SelectiveEkfAid::kImuQuat);

  const MagStatus& m = ekf.mag_status();
  SourceReport mag(Source::kMag);
  mag.fused_count = quat.by_decision[static_cast<size_t>(Decision::kFused)];
  mag.rejected_count = m.untrusted_samples;
  if (quat.last == Decision::kNone || quat.last == Decision::kRejectedNoMag) {
    mag.mark_not_available("no_mag");
  } else if (!m.reference_ready) {
    mag.mark_not_available("learning_reference");
  } else {
    const double thr_angle =
        (split ? p.heading_dip_tolerance_deg : p.disturbance_angle_threshold_deg) * kRadPerDeg;
    const double thr_q = p.quat_error_threshold_deg * kRadPerDeg;
    InnovationVector innov(2);
    innov << (m.disturbance_angle_deg - m.reference_angle_deg) * kRadPerDeg, m.quat_error_deg * kRadPerDeg;
    InnovationVector var(2);
    var << thr_angle * thr_angle, thr_q * thr_q;
    mag.set_innovation(innov, var);
    if (m.trusted) {
      mag.decision = SourceDecision::kFused;
      mag.last_fused_stamp_ns = quat.last_fused_stamp_ns;
    } else {
      mag.decision = SourceDecision::kRejected;
      mag.reason = m.moved_at_rest            ? "field_moved_at_rest"
                   : m.offset_pending         ? "hard_iron_pending"
                   : m.angle_test_failed      ? "disturbance_angle"
                   : m.norm_test_failed       ? "field_norm"
                   : m.quat_error_test_failed ? "quat_error"
                                              : "untrusted_hold";
    }
  }
  out.push_back(mag);

  for (const SelectiveEkfAid aid : {SelectiveEkfAid::kVisionAttitude, SelectiveEkfAid::kVisionPosition}) {
    const SourceStatus& st = ekf.status(aid);
    SourceReport r = from_status(ekf, aid);
    if (st.last != Decision::kNone && now - st.last_stamp_ns > recent_ns) {
      r.mark_not_available("no_recent_sample");
    }
    out.push_back(r);
  }
  out.push_back(from_status(ekf, SelectiveEkfAid::kAccelTilt));
  out.push_back(from_status(ekf, SelectiveEkfAid::kMagHeading));
  out.push_back(from_status(ekf, SelectiveEkfAid::kZeroRate));
  return out;
}

Eigen::Matrix3d attitude_covariance_world(const SelectiveEkf& ekf) { return ekf.attitude_covariance(); }

std::optional<Eigen::Matrix3d> SelectiveEkfFilter::attitude_covariance() const {
  if (!ekf_.initialized()) {
    return std::nullopt;
  }
  return attitude_covariance_world(ekf_);
}

bool SelectiveEkfFilter::take_published_imu_delay(double delay_s) {
  if (delay_configured_) {
    return false;
  }
  if (ekf_.initialized()) {
    ekf_.reset();  // the state's time is the IMU stamp minus the delay: restart on the new one
  }
  ekf_.set_imu_delay_s(delay_s);
  return true;
}

Eigen::Matrix<double, 9, 9> pose_covariance_world(const SelectiveEkfState& x,
                                                   const Eigen::Quaterniond& q_world_body) {
  // J maps the error state [w, th_body, b, t, v] to [p, v, th_world]: th_world = R th_body.
  Eigen::Matrix<double, 9, SelectiveEkf::kN> j = Eigen::Matrix<double, 9, SelectiveEkf::kN>::Zero();
  j.block<3, 3>(0, SelectiveEkf::kT).setIdentity();
  j.block<3, 3>(3, SelectiveEkf::kV).setIdentity();
  j.block<3, 3>(6, SelectiveEkf::kTh) = q_world_body.normalized().toRotationMatrix();
  return j * x.P_err * j.transpose();  // the estimate's error covariance
}

Eigen::Matrix<double, 9, 9> pose_covariance_world(const SelectiveEkf& ekf) {
  Eigen::Matrix<double, 9, 9> c = pose_covariance_world(ekf.state(), ekf.q_world_body());
  const Eigen::Matrix3d d = attitude_covariance_world(ekf) - c.bottomRightCorner<3, 3>();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (d + d.transpose()));
  c.bottomRightCorner<3, 3>() +=
      eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() * eig.eigenvectors().transpose();
  return c;
}

VisionPose to_vision_pose(const CameraPoseMeasurement& m) {
  VisionPose v;
  v.capture_stamp_ns = m.stamp_ns;
  v.q_world_camera = m.q_world_camera;
  v.p_world_camera_m = m.p_world_camera_m;
  const double var_p = m.covariance.diagonal().head<3>().mean();
  const double var_r = m.covariance.diagonal().tail<3>().mean();
  v.sigma_m = var_p > 0.0 && std::isfinite(var_p) ? std::sqrt(var_p) : std::nan("");
  v.sigma_rad = var_r > 0.0 && std::isfinite(var_r) ? std::sqrt(var_r) : std::nan("");
  // the camera's per-detection attitude covariance, whole (its heading is far better than its tilt)
  const Eigen::Matrix3d c_r = m.covariance.bottomRightCorner<3, 3>();
  if (selective_ekf_aids::attitude_covariance_ok(c_r)) {
    v.attitude_covariance_world = c_r;
  }
  return v;
}

}  // namespace poise
