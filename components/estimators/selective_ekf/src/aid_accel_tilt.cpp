// Aid source: the tilt from the accelerometer (ImuMeasurement::kSplit). z_up is the accelerometer
// low-passed in a gyro-propagated frame (preprocess), u = R(q)^T e_z; two rows e_i . (z_up x u) =
// e_i . dth with e_1, e_2 orthonormal and perpendicular to u. Variance per row: the spectral
// density in.tilt_sigma^2 / dt, times the external-acceleration inflation. Never gated.
#include "aid.h"

#include <cmath>

namespace poise::selective_ekf_aids {

namespace {

/// The two tilt rows on the [w, th, b] block with the bias rows of the gain zeroed (a Schmidt
/// consider update): K = P H^T S^-1 without its bias rows, P <- (I - K H) P (I - K H)^T + K R K^T.
/// Returns the innovation variances diag(S).
Eigen::Vector2d fuse_bias_considered(SelectiveEkfState& x, const Eigen::Matrix<double, 2, SelectiveEkf::kN>& h,
                                     const Eigen::Vector2d& innov, double r) {
  constexpr int kA = SelectiveEkf::kAttN;
  using MatA = Eigen::Matrix<double, kA, kA>;
  const MatA pa = x.P.topLeftCorner<kA, kA>();
  const Eigen::Matrix<double, 2, kA> ha = h.leftCols<kA>();
  const Eigen::Matrix2d s = ha * pa * ha.transpose() + r * Eigen::Matrix2d::Identity();
  Eigen::Matrix<double, kA, 2> k = pa * ha.transpose() * s.inverse();
  k.middleRows<3>(SelectiveEkf::kB).setZero();
  const MatA ikh = MatA::Identity() - k * ha;
  const MatA updated = ikh * pa * ikh.transpose() + r * k * k.transpose();
  x.P.topLeftCorner<kA, kA>() = 0.5 * (updated + updated.transpose());
  SelectiveEkf::Vec dx = SelectiveEkf::Vec::Zero();
  dx.head<kA>() = k * innov;
  inject(x, dx);
  return s.diagonal();
}

}  // namespace

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
  const Eigen::Vector3d cr = in.up_meas.cross(u);
  Eigen::Matrix<double, 2, SelectiveEkf::kN> h = Eigen::Matrix<double, 2, SelectiveEkf::kN>::Zero();
  h.block<1, 3>(0, SelectiveEkf::kTh) = e1.transpose();
  h.block<1, 3>(1, SelectiveEkf::kTh) = e2.transpose();
  const Eigen::Vector2d innov(e1.dot(cr), e2.dot(cr));
  const double r = in.tilt_sigma * in.tilt_sigma / in.dt_s * in.tilt_var_scale;
  // gate: none; fuse. After a start in motion the low-pass and the attitude both began at the
  // first sample, external acceleration and all; as the low-pass forgets it (over
  // accel_lowpass_tau_s) the innovation ramps, which is what a bias error looks like. For that
  // time constant the bias is a consider state of these rows (Schmidt): its gain is zero, P keeps
  // its uncertainty and the correlations (Joseph form for the gain used).
  if (c.x.pre.moving_start && c.x.pre.since_start_s < c.p.accel_lowpass_tau_s && !c.x.coupled) {
    st.innovation_variance.setZero();
    st.innovation_variance.head<2>() = fuse_bias_considered(c.x, h, innov, r);
    st.innovation.setZero();
    st.innovation.head<2>() = innov;
  } else {
    fuse<2>(c.x, h, innov, Eigen::Vector2d::Constant(r), kReportGateSigma, false, st);
  }
  // status
  record(st, Decision::kFused, in.stamp_ns, c.first_pass);
}

}  // namespace poise::selective_ekf_aids
