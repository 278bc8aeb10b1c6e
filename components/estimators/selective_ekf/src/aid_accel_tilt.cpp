// Aid source: the tilt from the accelerometer (ImuMeasurement::kSplit). z_up is the accelerometer
// low-passed in an almost inertial frame R_ib that predict_to turns with the state's rate, exactly
// as it predicts the attitude (preprocess), u = R(q)^T e_z; two rows e_i . (z_up x u) =
// e_i . (dth - R_ib^T e) with e_1, e_2 orthonormal and perpendicular to u. The frame's error is
// the prediction's own (the integrated rate error dw: gyro noise and bias error alike), the same
// error the attitude integrates; the low-pass keeps it less its low-passed past, which is the
// state e (kE, selective_ekf.h). Without e the frame's error was read as measurement noise
// independent of the attitude's, which integrates the same gyro noise (counted twice: averaged
// NEES 13 at 2 s and 0.05 on tilt from 10 s at rest, docs/SELECTIVE_EKF.md "The low-pass's
// error as a state"); it also carries what the former bias columns did. Variance per row: the
// spectral density in.tilt_sigma^2 / dt, times the external-acceleration inflation. Never gated.
#include "aid.h"

#include <cmath>

namespace poise::selective_ekf_aids {

void aid_accel_tilt(const AidContext& c, const ImuInput& in, SourceStatus& st) {
  // validate: a density needs an interval
  if (!(in.dt_s > 0.0)) {
    return;
  }
  // innovation: e1, e2 orthonormal, perpendicular to u. z_up x u = dth_perp (small angles), so the
  // rows are e_i . (z_up x u) = e_i . dth.
  const Eigen::Vector3d u = c.x.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();  // R^T e_z
  const Eigen::Vector3d a = std::abs(u.x()) < 0.6 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d e1 = u.cross(a).normalized();
  const Eigen::Vector3d e2 = u.cross(e1);
  // the low-passed up vector now (the bias correction of this step's earlier rows turned it)
  Eigen::Vector3d z_up;
  if (!safe_normalize(c.x.pre.q_ib.conjugate() * c.x.pre.lp_accel_i, z_up)) {
    z_up = in.up_meas;
  }
  const Eigen::Vector3d cr = z_up.cross(u);
  // the low-pass's error: its up vector is turned by exp(-R_ib^T e) against the truth (the
  // frame's prediction error less its low-passed past), so the rows measure e_i . (dth - R_ib^T e)
  const Eigen::Matrix3d m = -c.x.pre.q_ib.toRotationMatrix().transpose();
  Eigen::Matrix<double, 2, SelectiveEkf::kN> h = Eigen::Matrix<double, 2, SelectiveEkf::kN>::Zero();
  h.block<1, 3>(0, SelectiveEkf::kTh) = e1.transpose();
  h.block<1, 3>(1, SelectiveEkf::kTh) = e2.transpose();
  h.block<1, 3>(0, SelectiveEkf::kE) = e1.transpose() * m;
  h.block<1, 3>(1, SelectiveEkf::kE) = e2.transpose() * m;
  const Eigen::Vector2d innov(e1.dot(cr), e2.dot(cr));
  const double r = in.tilt_sigma * in.tilt_sigma / in.dt_s * in.tilt_var_scale;
  // the rows' real white noise (P_err): with the accelerometer's noise known, none: its low-passed
  // noise is part of e (an AR(1) state, preprocess), correlated over the low-pass's time constant
  // and far smaller per period than the design density above
  const Eigen::Vector2d r_err = Eigen::Vector2d::Constant(accel_noise_known(c.p) ? 0.0 : r);
  // gate: none; fuse. After a start in motion the low-pass and the attitude both began at the
  // first sample, external acceleration and all; as the low-pass forgets it (over
  // accel_lowpass_tau_s) the innovation ramps, which is what a bias error looks like. For that
  // time constant the bias is a consider state of these rows (Schmidt): its gain is zero, P keeps
  // its uncertainty and the correlations (Joseph form for the gain used).
  if (c.x.pre.moving_start && c.x.pre.since_start_s < c.p.accel_lowpass_tau_s && !c.x.coupled) {
    st.innovation_variance.setZero();
    st.innovation_variance.head<2>() = fuse_bias_considered<2>(c.x, h, innov, Eigen::Vector2d::Constant(r), r_err);
    st.innovation.setZero();
    st.innovation.head<2>() = innov;
  } else {
    fuse<2>(c.x, h, innov, Eigen::Vector2d::Constant(r), r_err, kReportGateSigma, false, st);
  }
  // status
  record(st, Decision::kFused, in.stamp_ns, c.first_pass);
}

}  // namespace poise::selective_ekf_aids
