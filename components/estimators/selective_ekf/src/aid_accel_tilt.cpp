// Aid source: the tilt from the accelerometer (ImuMeasurement::kSplit). z_up is the accelerometer
// low-passed in a gyro-propagated frame (preprocess), u = R(q)^T e_z; two rows e_i . (z_up x u) =
// e_i . dth with e_1, e_2 orthonormal and perpendicular to u. Variance per row: the spectral
// density in.tilt_sigma^2 / dt, times the external-acceleration inflation. Never gated.
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
  const Eigen::Vector3d cr = in.up_meas.cross(u);
  Eigen::Matrix<double, 2, SelectiveEkf::kN> h = Eigen::Matrix<double, 2, SelectiveEkf::kN>::Zero();
  h.block<1, 3>(0, SelectiveEkf::kTh) = e1.transpose();
  h.block<1, 3>(1, SelectiveEkf::kTh) = e2.transpose();
  const Eigen::Vector2d innov(e1.dot(cr), e2.dot(cr));
  const double r = in.tilt_sigma * in.tilt_sigma / in.dt_s * in.tilt_var_scale;
  // gate: none; fuse
  fuse<2>(c.x, h, innov, Eigen::Vector2d::Constant(r), kReportGateSigma, false, st);
  // status
  record(st, Decision::kFused, in.stamp_ns, c.first_pass);
}

}  // namespace poise::selective_ekf_aids
