// NEES of a published attitude covariance: the machinery every consistency figure goes through
// (poise eval broad, the demo report, the process comparison). Oracles: the chi-square law with
// three degrees of freedom (median 2.366, 95 % at 7.815) and closed forms.
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

namespace poise {
namespace {

constexpr double kExact = 1e-9;

TEST(Consistency, GivenAKnownRotationThenTheErrorIsTheWorldFrameRotationVectorToTheTruth) {
  const Eigen::Quaterniond q_est = quat_from_euler_zyx(0.3, -0.2, 1.1);
  const Eigen::Vector3d phi(0.01, -0.02, 0.03);  // world frame, rad
  const Eigen::Quaterniond q_true = quat_exp(phi) * q_est;
  const Eigen::Vector3d e = world_attitude_error(q_est, q_true);
  EXPECT_NEAR((e - phi).norm(), 0.0, kExact);
  // sign of the quaternions does not matter
  EXPECT_NEAR((world_attitude_error(Eigen::Quaterniond(-q_est.coeffs()), q_true) - phi).norm(), 0.0, kExact);
}

TEST(Consistency, GivenADiagonalCovarianceThenTheNeesIsTheSumOfNormalisedSquares) {
  const Eigen::Vector3d e(0.1, -0.2, 0.3);
  const Eigen::Matrix3d p = Eigen::Vector3d(0.01, 0.04, 0.09).asDiagonal();
  EXPECT_NEAR(attitude_nees(e, p), 1.0 + 1.0 + 1.0, kExact);
}

TEST(Consistency, GivenNoUsableCovarianceThenTheNeesIsNanAndCountedApart) {
  const Eigen::Vector3d e(0.1, 0.0, 0.0);
  EXPECT_TRUE(std::isnan(attitude_nees(e, Eigen::Matrix3d::Zero())));                 // the old Gauss-Newton
  EXPECT_TRUE(std::isnan(attitude_nees(e, -Eigen::Matrix3d::Identity())));            // REP 145's -1
  EXPECT_TRUE(std::isnan(attitude_nees(e, Eigen::Matrix3d::Constant(std::nan("")))));  // none published
  Eigen::Matrix3d asym = Eigen::Matrix3d::Identity();
  asym(0, 1) = 0.5;
  EXPECT_TRUE(std::isnan(attitude_nees(e, asym)));
  NeesSummary s;
  s.add(std::nan(""));
  s.add(1.0);
  EXPECT_EQ(s.samples(), 1u);
  EXPECT_EQ(s.without_covariance(), 1u);
  NeesSummary none;
  EXPECT_TRUE(std::isnan(none.median()));
  EXPECT_TRUE(std::isnan(none.fraction_inside()));
}

TEST(Consistency, GivenErrorsDrawnFromTheCovarianceThenMedianAndFractionInsideFollowChiSquareWithThreeDof) {
  const unsigned seed = 31;
  std::printf("seed %u\n", seed);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  Eigen::Matrix3d a;
  a << 0.02, 0.0, 0.0, 0.005, 0.01, 0.0, -0.003, 0.002, 0.05;  // a correlated covariance, rad
  const Eigen::Matrix3d p = a * a.transpose();
  const Eigen::Quaterniond q_true = quat_from_euler_zyx(0.1, 0.2, -2.0);
  NeesSummary s;
  NeesSummary half;  // the first half, merged below: the pooled figures are the same law
  constexpr int kSamples = 20000;
  for (int k = 0; k < kSamples; ++k) {
    const Eigen::Vector3d e = a * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    const Eigen::Quaterniond q_est = quat_exp(-e) * q_true;  // q_true q_est^-1 = exp(e)
    (k < kSamples / 2 ? half : s).add(attitude_nees(world_attitude_error(q_est, q_true), p));
  }
  s.merge(half);
  ASSERT_EQ(s.samples(), static_cast<size_t>(kSamples));
  // 20000 samples: the sample median's standard error is about 0.02, the fraction's 0.0015
  constexpr double kMedianTol = 0.08;
  constexpr double kFractionTol = 0.006;
  EXPECT_NEAR(s.median(), kNeesMedianDof3, kMedianTol);
  EXPECT_NEAR(s.fraction_inside(kNees95Dof3), 0.95, kFractionTol);
}

}  // namespace
}  // namespace poise
