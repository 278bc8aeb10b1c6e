// Aid source: the gyro. Rows y = w + b, H = [I 0 I 0 0] (selective_ekf.h), every IMU sample; never
// gated (the test ratio against kReportGateSigma is reported only).
#include "aid.h"

namespace poise::selective_ekf_aids {

void aid_gyro(const AidContext& c, const ImuInput& in, SourceStatus& st) {
  // validate: every sample the filter accepted carries a gyro
  // innovation
  Eigen::Matrix<double, 3, SelectiveEkf::kN> h = Eigen::Matrix<double, 3, SelectiveEkf::kN>::Zero();
  h.middleCols<3>(SelectiveEkf::kW).setIdentity();
  h.middleCols<3>(SelectiveEkf::kB).setIdentity();
  const double r = c.p.sigma_gyro_rps * c.p.sigma_gyro_rps;
  // gate: none; fuse
  // P_err: the gyro's own white noise over the sample interval when known
  fuse<3>(c.x, h, in.gyro - c.x.w_rps - c.x.b_rps, Eigen::Vector3d::Constant(r),
          Eigen::Vector3d::Constant(err_gyro_variance(c.p, in.dt_s)), kReportGateSigma, false, st);
  // status
  record(st, Decision::kFused, in.stamp_ns, c.first_pass);
}

}  // namespace poise::selective_ekf_aids
