// DirectionKf against the textbook Kalman filter written out with 6x6 matrices (independent
// oracle): F = blkdiag(A, c I), Q = blkdiag(h^2 sigma_G^2 [u x][u x]^T, (c^2/3 |e|^2 + sigma^2) I),
// H = [k I | I], K = P H^T (H P H^T + M)^-1. The filter's closed form for c = 0 and its scalar
// updates for c > 0 must give the same state and covariance; its tangent form (unit directions)
// must stay within a percent of the textbook filter's own standard deviation.
#include "poise/parallel_kf/direction_kf.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <random>

namespace poise {
namespace {

using Vector6 = Eigen::Matrix<double, 6, 1>;
using Matrix6 = Eigen::Matrix<double, 6, 6>;

// Rounding of a dozen products of values of order 1 (relative), and of the covariances' scale.
constexpr double kStateTol = 1e-12;     // unit-vector components and uT (order 1-50)
constexpr double kCovRelTol = 1e-9;     // relative to the largest covariance entry
constexpr uint32_t kSeed = 7;

struct Oracle {
  Vector6 x;
  Matrix6 p;
};

Oracle textbook_step(const Oracle& prior, const Eigen::Matrix3d& a, double h, double c, double sigma_g,
                     double sigma, double k, const Eigen::Vector3d& z) {
  const Eigen::Vector3d u = prior.x.head<3>();
  const Eigen::Vector3d e = prior.x.tail<3>();
  Matrix6 f = Matrix6::Zero();
  f.topLeftCorner<3, 3>() = a;
  f.bottomRightCorner<3, 3>() = c * Eigen::Matrix3d::Identity();
  Matrix6 q = Matrix6::Zero();
  const Eigen::Matrix3d ux = skew(u);
  q.topLeftCorner<3, 3>() = h * h * sigma_g * sigma_g * ux * ux.transpose();
  q.bottomRightCorner<3, 3>() = (c * c / 3.0 * e.squaredNorm() + sigma * sigma) * Eigen::Matrix3d::Identity();
  Oracle o;
  o.x = f * prior.x;
  o.p = f * prior.p * f.transpose() + q;
  Eigen::Matrix<double, 3, 6> hm;
  hm << k * Eigen::Matrix3d::Identity(), Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d s = hm * o.p * hm.transpose() + sigma * sigma * Eigen::Matrix3d::Identity();
  const Eigen::Matrix<double, 6, 3> gain = o.p * hm.transpose() * s.inverse();
  o.x += gain * (z - hm * o.x);
  o.p = (Matrix6::Identity() - gain * hm) * o.p;
  return o;
}

DirectionKfParams test_params(double c, double sigma, bool renormalize) {
  DirectionKfParams prm;
  prm.sigma_gyro_rps = 0.01;
  prm.sigma_meas = sigma;
  prm.c = c;
  prm.exact_rotation = true;
  prm.renormalize = renormalize;
  return prm;
}

// Both filters at the same start: u0, covariance diag(1e-2 I, 4 I)
Oracle start(DirectionKf& kf) {
  const Eigen::Vector3d u0 = Eigen::Vector3d(0.3, -0.2, 0.93).normalized();
  kf.reset(u0, 1e-2, 4.0);
  Oracle o;
  o.x << u0, Eigen::Vector3d::Zero();
  o.p = kf.covariance();
  return o;
}

void run_against_oracle(double c, double k, double sigma) {
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> n01(0.0, 1.0);
  const DirectionKfParams prm = test_params(c, sigma, false);  // the oracle does not renormalise
  DirectionKf kf(prm);
  Oracle o = start(kf);
  const double h = 0.0035;  // s
  for (int step = 0; step < 200; ++step) {
    const Eigen::Vector3d w(0.5 * n01(rng), 0.5 * n01(rng), 0.5 * n01(rng));  // rad/s
    const Eigen::Matrix3d a = rot_exp(-h * w);
    const Eigen::Vector3d truth = a * o.x.head<3>();
    const Eigen::Vector3d z = k * truth + Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * sigma * 3.0;
    o = textbook_step(o, a, h, c, prm.sigma_gyro_rps, sigma, k, z);
    kf.predict_with_transition(a, h);
    kf.correct(z, k);
    const double p_scale = o.p.cwiseAbs().maxCoeff();
    for (int i = 0; i < 3; ++i) {
      ASSERT_NEAR(kf.u()[i], o.x[i], kStateTol) << "step " << step << " u[" << i << "]";
      ASSERT_NEAR(kf.e()[i], o.x[3 + i], kStateTol * k) << "step " << step << " e[" << i << "]";
    }
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) {
        ASSERT_NEAR(kf.covariance()(i, j), o.p(i, j), kCovRelTol * p_scale) << "step " << step << " P(" << i << "," << j << ")";
      }
    }
  }
}

TEST(DirectionKf, GivenCZeroWhenUpdatedInClosedFormThenStateAndCovarianceEqualTheTextbookFilter) {
  run_against_oracle(0.0, 9.81, 0.0003);  // KF1 of the default: accelerometer, m/s^2
  run_against_oracle(0.0, 50.0, 0.4);     // KF2 of the default: magnetometer, uT
}

TEST(DirectionKf, GivenCPositiveWhenUpdatedBySequentialScalarsThenStateAndCovarianceEqualTheTextbookFilter) {
  run_against_oracle(0.1, 9.81, 0.04);  // the paper's KF1
  run_against_oracle(0.1, 50.0, 0.2);   // the paper's KF2
}

// The tangent form (unit directions: exact rotation, renormalised; c = 0) keeps P11 as alpha (I -
// u u^T) + beta u u^T. Oracle: the textbook filter above with u renormalised after each update
// (what the full form did), fed the same rotations and readings with the noise the filter is told
// (a consistent filter: its corrections are as large as its sigma says). The form's one approximation (the posterior's eigenvectors taken along with u) must be
// negligible against the uncertainty the filter reports: every step, u within 1 % of the
// oracle's own standard deviation across u, the variance across u within 1 % of the oracle's, e
// within 1 % of the oracle's standard deviation of e.
void run_tangent_against_oracle(double k, double sigma) {
  constexpr double kShareOfSigma = 0.01;  // of the oracle's own standard deviation
  constexpr double kVarianceRel = 0.01;   // relative, of the variance across u
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> n01(0.0, 1.0);
  const DirectionKfParams prm = test_params(0.0, sigma, true);
  DirectionKf kf(prm);
  Oracle o = start(kf);
  Eigen::Vector3d truth = o.x.head<3>();
  const double h = 0.0035;  // s
  for (int step = 0; step < 2000; ++step) {
    const Eigen::Vector3d w(0.5 * n01(rng), 0.5 * n01(rng), 0.5 * n01(rng));  // rad/s
    const Eigen::Matrix3d a = rot_exp(-h * w);
    truth = a * truth;
    const Eigen::Vector3d z = k * truth + Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * sigma;
    o = textbook_step(o, a, h, 0.0, prm.sigma_gyro_rps, sigma, k, z);
    o.x.head<3>().normalize();
    kf.predict_with_transition(a, h);
    kf.correct(z, k);
    const Eigen::Vector3d u = o.x.head<3>();
    const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - u * u.transpose();
    const double var_across = 0.5 * (across * o.p.topLeftCorner<3, 3>() * across).trace();
    const double var_across_kf = 0.5 * (across * kf.covariance().topLeftCorner<3, 3>() * across).trace();
    const double var_e = o.p.bottomRightCorner<3, 3>().trace() / 3.0;
    ASSERT_LE((kf.u() - u).norm(), kShareOfSigma * std::sqrt(var_across)) << "step " << step;
    ASSERT_LE(std::abs(var_across_kf / var_across - 1.0), kVarianceRel) << "step " << step;
    ASSERT_LE((kf.e() - o.x.tail<3>()).norm(), kShareOfSigma * std::sqrt(var_e)) << "step " << step;
    ASSERT_NEAR(kf.u().norm(), 1.0, kStateTol) << "step " << step;
  }
}

TEST(DirectionKf, GivenUnitDirectionsInTheTangentFormThenStateAndCovarianceStayWithinAPercentOfTheTextbookFiltersSigma) {
  run_tangent_against_oracle(9.81, 0.0003);  // KF1 of the default
  run_tangent_against_oracle(50.0, 0.4);     // KF2 of the default
}

// New parameters that do not keep the tangent form (here: no renormalisation) take P over in full:
// the covariance the filter had is the one it goes on from, and the next update is the textbook's.
TEST(DirectionKf, GivenTheTangentFormWhenTheParametersChangeThenTheFullFormGoesOnFromTheSameCovariance) {
  DirectionKf kf(test_params(0.0, 0.0003, true));
  Oracle o = start(kf);
  const Eigen::Matrix3d a = rot_exp(Eigen::Vector3d(0.01, -0.02, 0.005));
  for (int step = 0; step < 20; ++step) {
    kf.predict_with_transition(a, 0.0035);
    kf.correct(9.81 * kf.u() + Eigen::Vector3d(0.0002, -0.0001, 0.0003), 9.81);
  }
  o.x << kf.u(), kf.e();
  o.p = kf.covariance();
  const DirectionKfParams full = test_params(0.0, 0.0003, false);
  kf.set_params(full);
  const double p_scale = o.p.cwiseAbs().maxCoeff();
  EXPECT_LE((kf.covariance() - o.p).cwiseAbs().maxCoeff(), kCovRelTol * p_scale);
  const Eigen::Vector3d z = 9.81 * (a * kf.u()) + Eigen::Vector3d(0.0003, 0.0002, -0.0001);
  o = textbook_step(o, a, 0.0035, 0.0, full.sigma_gyro_rps, full.sigma_meas, 9.81, z);
  kf.predict_with_transition(a, 0.0035);
  kf.correct(z, 9.81);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(kf.u()[i], o.x[i], kStateTol) << "u[" << i << "]";
  }
  EXPECT_LE((kf.covariance() - o.p).cwiseAbs().maxCoeff(), kCovRelTol * p_scale);
}

TEST(DirectionKf, SymmetricInverseIsTheInverse) {
  Eigen::Matrix3d m;
  m << 4.0, 1.0, -0.5, 1.0, 3.0, 0.25, -0.5, 0.25, 2.0;
  const Eigen::Matrix3d inv = DirectionKf::symmetric_inverse(m);
  EXPECT_TRUE((inv * m).isApprox(Eigen::Matrix3d::Identity(), 1e-14));
  EXPECT_EQ(inv(0, 1), inv(1, 0));
  EXPECT_EQ(inv(0, 2), inv(2, 0));
  EXPECT_EQ(inv(1, 2), inv(2, 1));
}

}  // namespace
}  // namespace poise
