// Aid source: rest. While the rest detector (preprocess) says rest:
//   bias   its low-passed gyro (rest_filter_tau_s) measures the bias: y = gyro_lp = b + n,
//          H = [0 0 I 0 0], variance sigma_gyro^2 + sigma_rest^2 per sample (the low-pass of white
//          noise keeps the raw samples' low-frequency density, so fusing it every sample with their
//          variance adds their information);
//   rate   the rate is zero: y = 0 = w, H = [I 0 0 0 0], variance sigma_rest^2, with the bias as a
//          consider state (its gain zeroed, update.h), and only while the rate is consistent with
//          rest: w^T (P_ww + sigma_rest^2 I)^-1 w <= 7.815 (chi-square, 3 degrees of freedom, 95 %).
//          The attitude then stops integrating gyro noise at rest.
// The detector lags: it still says rest for the first samples of a motion that starts slowly
// (below its 2 deg/s). A zero rate asserted there took the sample's rate as bias (with the gyro
// row: 0.5 deg/s at the tour's 2 s pause, docs/SELECTIVE_EKF.md) and held the attitude while the
// body turned. In the low-pass those samples weigh dt / tau each; the rate row no longer reaches
// the bias, and it stops once the rate stands out of the noise.
#include "aid.h"

#include "poise/core/consistency.h"

namespace poise::selective_ekf_aids {

namespace {

/// fuse_bias_considered of the three rows that read the rate itself, H = [I 0 0 0 0 0] (the rest
/// aid's zero rate), bit for bit, without the dense products (for cost: they were a third of the
/// filter's instructions on BROAD). With H a selection, H P H^T is P_ww and P H^T is P's rate
/// columns (one non-zero term in each sum); I - K H is I but in its rate columns, so each sum of
/// (I - K H) P (I - K H)^T takes the three rate terms in the dense product's order, then the
/// identity's term; K R K^T has three terms per sum. Coupled blocks: fuse_bias_considered.
Eigen::Vector3d fuse_rate_bias_considered(SelectiveEkfState& x, const Eigen::Vector3d& innov,
                                          const Eigen::Vector3d& r_diag, const Eigen::Vector3d& r_err_diag) {
  constexpr int kN = SelectiveEkf::kN;
  constexpr int kA = SelectiveEkf::kAttN;
  Eigen::Matrix<double, 3, kN> h = Eigen::Matrix<double, 3, kN>::Zero();
  h.middleCols<3>(SelectiveEkf::kW).setIdentity();
  static_assert(SelectiveEkf::kW == 0, "the rate's columns lead the attitude block");
  if (x.coupled) {
    return fuse_bias_considered<3>(x, h, innov, r_diag, r_err_diag);
  }
  auto pa = x.P.topLeftCorner<kA, kA>();
  Eigen::Matrix3d s = pa.topLeftCorner<3, 3>();
  s.diagonal() += r_diag;
  const Eigen::Matrix3d s_inv = s.inverse();
  Eigen::Matrix<double, kN, 3> k = Eigen::Matrix<double, kN, 3>::Zero();
  k.topRows<kA>() = pa.leftCols<3>().lazyProduct(s_inv);
  k.middleRows<3>(SelectiveEkf::kB).setZero();  // the bias considered
  const Eigen::Matrix<double, kA, 3> ka = k.topRows<kA>();
  const Eigen::Matrix<double, kA, 3> ikh_w = Eigen::Matrix<double, kA, 3>::Identity() - ka;  // (I - K H)'s rate columns
  Eigen::Matrix<double, kA, kA> m1 = ikh_w.lazyProduct(pa.topRows<3>());  // (I - K H) P
  m1.bottomRows<kA - 3>() += pa.bottomRows<kA - 3>();
  Eigen::Matrix<double, kA, kA> m2 = m1.leftCols<3>().lazyProduct(ikh_w.transpose());  // ... (I - K H)^T
  m2.rightCols<kA - 3>() += m1.rightCols<kA - 3>();
  const Eigen::Matrix<double, kA, 3> kr = ka * r_diag.asDiagonal();
  const Eigen::Matrix<double, kA, kA> updated = m2 + kr.lazyProduct(ka.transpose());
  pa = 0.5 * (updated + updated.transpose());
  update_error_covariance<3>(x, k, h, r_err_diag, true);
  inject(x, k * innov);
  return s.diagonal();
}

}  // namespace

void aid_zero_rate(const AidContext& c, const ImuInput& in, SourceStatus& st) {
  // validate: at rest only (no decision otherwise: the source has no sample)
  if (!in.rest) {
    return;
  }
  // bias: innovation, fuse (no gate)
  Eigen::Matrix<double, 3, SelectiveEkf::kN> h = Eigen::Matrix<double, 3, SelectiveEkf::kN>::Zero();
  h.middleCols<3>(SelectiveEkf::kB).setIdentity();
  const double r_rest = c.p.sigma_rest_rate_rps * c.p.sigma_rest_rate_rps;
  const double r_bias = c.p.sigma_gyro_rps * c.p.sigma_gyro_rps + r_rest;
  // (P_err: the gyro's own white noise when known)
  const double r_bias_err = err_gyro_variance(c.p, in.dt_s) + r_rest;
  fuse<3>(c.x, h, c.x.pre.rest_detector.gyro_lp - c.x.b_rps, Eigen::Vector3d::Constant(r_bias),
          Eigen::Vector3d::Constant(r_bias_err), kReportGateSigma, false, st);
  // rate: gate (consistent with rest), fuse with the bias considered
  const Eigen::Matrix3d s_w =
      c.x.P.block<3, 3>(SelectiveEkf::kW, SelectiveEkf::kW) + r_rest * Eigen::Matrix3d::Identity();
  if (c.x.w_rps.dot(s_w.ldlt().solve(c.x.w_rps)) <= kNees95Dof3) {  // chi-square, 3 dof, 95 %
    fuse_rate_bias_considered(c.x, -c.x.w_rps, Eigen::Vector3d::Constant(r_rest), Eigen::Vector3d::Constant(r_rest));
  }
  // status
  record(st, Decision::kFused, in.stamp_ns, c.first_pass);
}

}  // namespace poise::selective_ekf_aids
