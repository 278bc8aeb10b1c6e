// Aid source: the zero rate at rest. Rows y = 0 = w, H = [I 0 0 0 0] (with the gyro row they
// observe the bias b directly); only while the rest detector (preprocess) says rest.
#include "aid.h"

namespace poise::selective_ekf_aids {

void aid_zero_rate(const AidContext& c, const ImuInput& in, SourceStatus& st) {
  // validate: at rest only (no decision otherwise: the source has no sample)
  if (!in.rest) {
    return;
  }
  // innovation
  Eigen::Matrix<double, 3, SelectiveEkf::kN> h = Eigen::Matrix<double, 3, SelectiveEkf::kN>::Zero();
  h.middleCols<3>(SelectiveEkf::kW).setIdentity();
  const double r = c.p.sigma_rest_rate_rps * c.p.sigma_rest_rate_rps;
  // gate: none; fuse
  fuse<3>(c.x, h, -c.x.w_rps, Eigen::Vector3d::Constant(r), kReportGateSigma, false, st);
  // status
  record(st, Decision::kFused, in.stamp_ns, c.first_pass);
}

}  // namespace poise::selective_ekf_aids
