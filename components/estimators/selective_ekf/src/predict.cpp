// Prediction to a requested time (issue 36: the renderer's display time): the output attitude
// turned on with the estimated body rate, q(t) = q_world_body() (x) exp(w (t - t_newest)), and the
// published covariance grown by what the horizon adds to the state's attitude covariance when the
// state is propagated over it as the filter would (rate error through J_r(w h) h, the attitude and
// angular-acceleration process noise; F and Q of the prediction (3)-(4)): growth(delay + horizon)
// - growth(delay), world frame.
#include "aid.h"

#include <algorithm>

namespace poise {
namespace {

/// The attitude block of the state propagated over h at a constant estimated rate, world frame.
Eigen::Matrix3d propagated_attitude_covariance(const SelectiveEkfState& x, const SelectiveEkfParams& p, double h) {
  constexpr int kW = SelectiveEkf::kW;
  constexpr int kTh = SelectiveEkf::kTh;
  const Eigen::Vector3d wh = x.w_rps * h;
  const Eigen::Quaterniond dq = quat_exp(wh);
  const Eigen::Matrix3d a = dq.toRotationMatrix().transpose();  // J_dth'_dth = Exp(w h)^T
  const Eigen::Matrix3d b = so3_right_jacobian(wh) * h;         // J_dth'_dw
  const Eigen::Matrix3d p_tt = x.P_err.block<3, 3>(kTh, kTh);
  const Eigen::Matrix3d p_tw = x.P_err.block<3, 3>(kTh, kW);
  const Eigen::Matrix3d p_ww = x.P_err.block<3, 3>(kW, kW);
  const Eigen::Matrix3d atw = a * p_tw * b.transpose();
  Eigen::Matrix3d body = a * p_tt * a.transpose() + atw + atw.transpose() + b * p_ww * b.transpose();
  // continuous white noise over h: attitude walk q h, angular acceleration q h^3 / 3
  body.diagonal().array() += selective_ekf_aids::err_attitude_walk2(p) * h +
                             p.sigma_angular_accel * p.sigma_angular_accel * h * h * h / 3.0;
  const Eigen::Matrix3d r = (x.q_world_body * dq).toRotationMatrix();
  return r * body * r.transpose();
}

}  // namespace

PredictedAttitude SelectiveEkf::predict(int64_t t_ns) const {
  PredictedAttitude out;
  out.q_world_body = q_world_body();
  out.covariance = attitude_covariance();
  out.rate_rps = x_.w_rps;
  out.stamp_ns = std::max(t_ns, last_imu_stamp_ns_);
  if (!initialized_ || last_imu_stamp_ns_ < 0 || out.stamp_ns <= last_imu_stamp_ns_) {
    out.stamp_ns = last_imu_stamp_ns_;
    return out;
  }
  const double horizon_s = static_cast<double>(out.stamp_ns - last_imu_stamp_ns_) * selective_ekf_aids::kNsToS;
  const double delay_s = static_cast<double>(current_delay_ns()) * selective_ekf_aids::kNsToS;
  out.horizon_s = horizon_s;
  out.q_world_body = quat_canonical((out.q_world_body * quat_exp(x_.w_rps * horizon_s)).normalized());
  const Eigen::Matrix3d grown = out.covariance + propagated_attitude_covariance(x_, p_, delay_s + horizon_s) -
                                propagated_attitude_covariance(x_, p_, delay_s);
  out.covariance = 0.5 * (grown + grown.transpose());
  return out;
}

PredictedAttitude SelectiveEkf::predict_horizon() const {
  return predict(last_imu_stamp_ns_ + selective_ekf_aids::seconds_to_ns(p_.predict_horizon_s));
}

}  // namespace poise
