// Property tests of the attitude-math layer (closed forms, round trips, Jacobians vs numerical
// perturbation). Seeded randomness; the seed is printed on failure via SCOPED_TRACE.
#include "poise/core/attitude.h"
#include "poise/core/sample_check.h"

#include <gtest/gtest.h>

#include <random>

namespace poise {
namespace {

constexpr uint32_t kSeed = 20260311;
constexpr int kTrials = 500;
constexpr double kRoundTripTol = 1e-9;       // dimensionless / rad
constexpr double kJacobianTol = 1e-6;        // numerical-vs-analytic, per entry
constexpr double kNumericStep = 1e-7;        // rad

Eigen::Vector3d random_rotvec(std::mt19937& rng, double max_angle) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Vector3d axis(u(rng), u(rng), u(rng));
  while (axis.norm() < 1e-3) {
    axis = Eigen::Vector3d(u(rng), u(rng), u(rng));
  }
  std::uniform_real_distribution<double> a(0.0, max_angle);
  return axis.normalized() * a(rng);
}

Eigen::Quaterniond random_quat(std::mt19937& rng) { return quat_exp(random_rotvec(rng, kPi * 0.999)); }

TEST(Attitude, SkewIsCrossProductAndUnskewInverts) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  std::mt19937 rng(kSeed);
  for (int i = 0; i < kTrials; ++i) {
    const Eigen::Vector3d a = random_rotvec(rng, 3.0);
    const Eigen::Vector3d b = random_rotvec(rng, 3.0);
    EXPECT_LT((skew(a) * b - a.cross(b)).norm(), kRoundTripTol);
    EXPECT_LT((unskew(skew(a)) - a).norm(), kRoundTripTol);
  }
}

TEST(Attitude, ExpLogRoundTrip) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  std::mt19937 rng(kSeed);
  for (int i = 0; i < kTrials; ++i) {
    const Eigen::Quaterniond q = random_quat(rng);
    EXPECT_LT(quat_angle_between(quat_exp(quat_log(q)), q), kRoundTripTol);
    const Eigen::Vector3d phi = random_rotvec(rng, kPi * 0.999);
    EXPECT_LT((quat_log(quat_exp(phi)) - phi).norm(), kRoundTripTol);
    EXPECT_LT((rot_log(rot_exp(phi)) - phi).norm(), 1e-8);
  }
  // Small angles (series branch) and identity.
  const Eigen::Vector3d tiny(1e-9, -2e-9, 3e-9);
  EXPECT_LT((quat_log(quat_exp(tiny)) - tiny).norm(), 1e-18);
  EXPECT_LT(quat_log(Eigen::Quaterniond::Identity()).norm(), 1e-15);
}

TEST(Attitude, ExpMatchesAngleAxis) {
  const Eigen::Vector3d phi(0.3, -0.2, 0.9);
  const Eigen::Quaterniond ref(Eigen::AngleAxisd(phi.norm(), phi.normalized()));
  EXPECT_LT(quat_angle_between(quat_exp(phi), ref), kRoundTripTol);
}

TEST(Attitude, ExpSeriesBranchMatchesTrigonometryAndIsUnit) {
  // Below 0.05 rad quat_exp uses a series; the oracle is Eigen's AngleAxis (sin/cos).
  constexpr double kCoeffTol = 1e-15;  // per coefficient: rounding, the truncation is < 1e-17
  for (double angle : {1e-12, 1e-6, 1e-3, 0.01, 0.049999, 0.05, 0.2}) {
    const Eigen::Vector3d axis = Eigen::Vector3d(0.3, -0.8, 0.52).normalized();
    const Eigen::Quaterniond q = quat_exp(angle * axis);
    const Eigen::Quaterniond ref(Eigen::AngleAxisd(angle, axis));
    EXPECT_LT((q.coeffs() - ref.coeffs()).cwiseAbs().maxCoeff(), kCoeffTol) << angle;
    EXPECT_NEAR(q.norm(), 1.0, kCoeffTol) << angle;
  }
}

TEST(Attitude, WxyzStorageRoundTrip) {
  const Eigen::Quaterniond q(0.5, -0.5, 0.5, 0.5);
  const auto a = quat_to_wxyz(q);
  EXPECT_DOUBLE_EQ(a[0], 0.5);
  EXPECT_DOUBLE_EQ(a[1], -0.5);
  const Eigen::Quaterniond back = quat_from_wxyz(a);
  EXPECT_EQ(back.coeffs(), q.coeffs());
  EXPECT_EQ(quat_from_wxyz(quat_to_wxyz_vec(q)).coeffs(), q.coeffs());
}

TEST(Attitude, CanonicalHasNonNegativeWAndUnitNorm) {
  const Eigen::Quaterniond q(-2.0, 0.0, 2.0, 0.0);
  const Eigen::Quaterniond c = quat_canonical(q);
  EXPECT_GE(c.w(), 0.0);
  EXPECT_NEAR(c.norm(), 1.0, kRoundTripTol);
  EXPECT_LT(quat_angle_between(c, q.normalized()), kRoundTripTol);
  const Eigen::Quaterniond nan_q(std::nan(""), 0, 0, 0);
  EXPECT_EQ(quat_canonical(nan_q).coeffs(), Eigen::Quaterniond::Identity().coeffs());
}

TEST(Attitude, EulerRoundTripAndClosedForms) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  std::mt19937 rng(kSeed);
  std::uniform_real_distribution<double> ang(-3.1, 3.1);
  std::uniform_real_distribution<double> pit(-1.5, 1.5);
  for (int i = 0; i < kTrials; ++i) {
    const Eigen::Vector3d rpy(ang(rng), pit(rng), ang(rng));
    const Eigen::Vector3d back = euler_zyx_from_quat(quat_from_euler_zyx(rpy.x(), rpy.y(), rpy.z()));
    EXPECT_LT((back - rpy).norm(), 1e-8);
  }
  // A pure 90 deg yaw maps body x onto world y (ENU: east -> north).
  const Eigen::Quaterniond q = quat_from_euler_zyx(0.0, 0.0, kPi / 2.0);
  EXPECT_LT((q * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), kRoundTripTol);
}

TEST(Attitude, FromTwoVectorsMapsAndIsShortest) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  std::mt19937 rng(kSeed);
  for (int i = 0; i < kTrials; ++i) {
    const Eigen::Vector3d a = random_rotvec(rng, 5.0);
    const Eigen::Vector3d b = random_rotvec(rng, 5.0);
    const Eigen::Quaterniond q = quat_from_two_vectors(a, b);
    EXPECT_LT((q * a.normalized() - b.normalized()).norm(), 1e-9);
    EXPECT_NEAR(2.0 * std::atan2(q.vec().norm(), std::abs(q.w())), angle_between_vectors(a, b), 1e-9);
  }
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  const Eigen::Quaterniond flip = quat_from_two_vectors(x, -x);
  EXPECT_LT((flip * x + x).norm(), 1e-12);
}

TEST(Attitude, RotateByShortestEqualsTheShortestRotationQuaternion) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  std::mt19937 rng(kSeed);
  for (int i = 0; i < kTrials; ++i) {
    const Eigen::Vector3d a = random_rotvec(rng, 5.0).normalized();
    const Eigen::Vector3d b = random_rotvec(rng, 5.0).normalized();
    const Eigen::Vector3d v = random_rotvec(rng, 5.0);
    if (a.dot(b) < -0.999) {
      continue;  // near anti-parallel: the axis is ill-defined for both
    }
    EXPECT_LT((rotate_by_shortest(a, b, v) - quat_from_two_vectors(a, b) * v).norm(), 1e-9 * (1.0 + v.norm()));
  }
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  EXPECT_EQ(rotate_by_shortest(x, -x, Eigen::Vector3d(1, 2, 3)), Eigen::Vector3d(1, 2, 3));  // refused
}

TEST(Attitude, RightJacobianMatchesNumericalPerturbation) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  std::mt19937 rng(kSeed);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d phi = random_rotvec(rng, 2.5);
    const Eigen::Matrix3d jr = so3_right_jacobian(phi);
    const Eigen::Matrix3d jr_inv = so3_right_jacobian_inv(phi);
    Eigen::Matrix3d numeric;
    Eigen::Matrix3d numeric_inv;
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector3d d = kNumericStep * Eigen::Vector3d::Unit(c);
      // exp(phi + d) = exp(phi) exp(J_r d)  =>  J_r d = log(exp(phi)^-1 exp(phi + d))
      numeric.col(c) = quat_log(quat_exp(phi).conjugate() * quat_exp(phi + d)) / kNumericStep;
      // log(exp(phi) exp(d)) = phi + J_r^-1 d
      numeric_inv.col(c) = (quat_log(quat_exp(phi) * quat_exp(d)) - phi) / kNumericStep;
    }
    EXPECT_LT((numeric - jr).cwiseAbs().maxCoeff(), kJacobianTol);
    EXPECT_LT((numeric_inv - jr_inv).cwiseAbs().maxCoeff(), kJacobianTol);
    EXPECT_LT((jr * jr_inv - Eigen::Matrix3d::Identity()).norm(), 1e-9);
  }
}

TEST(Attitude, RotateJacobianMatchesNumericalPerturbation) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  std::mt19937 rng(kSeed);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Quaterniond q = random_quat(rng);
    const Eigen::Vector3d v = random_rotvec(rng, 3.0);
    const Eigen::Matrix3d j = J_rotate_right_perturbation(q, v);
    Eigen::Matrix3d numeric;
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector3d d = kNumericStep * Eigen::Vector3d::Unit(c);
      numeric.col(c) = ((q * quat_exp(d)) * v - q * v) / kNumericStep;
    }
    EXPECT_LT((numeric - j).cwiseAbs().maxCoeff(), kJacobianTol);
  }
}

TEST(Attitude, IntegrateBodyRateIsExactForConstantRate) {
  const Eigen::Vector3d w(0.1, -0.4, 0.7);
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  const double dt = 0.01;
  for (int i = 0; i < 100; ++i) {
    q = quat_integrate_body_rate(q, w, dt);
  }
  EXPECT_LT(quat_angle_between(q, quat_exp(w * 1.0)), 1e-12);
}

TEST(Attitude, AxesFromUpForwardAndEnuNwu) {
  // Body aligned with NWU: up = body z, field direction = north (body x) dipping down.
  Eigen::Matrix3d r_body_world;
  ASSERT_TRUE(body_world_axes_from_up_forward(Eigen::Vector3d::UnitZ(),
                                              Eigen::Vector3d(0.5, 0.0, -0.8), r_body_world));
  EXPECT_LT((r_body_world - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_FALSE(body_world_axes_from_up_forward(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitZ(),
                                               r_body_world));
  // NWU north (x) is ENU y; NWU west (y) is ENU -x.
  EXPECT_LT((rot_enu_nwu() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), 1e-15);
  EXPECT_LT((rot_enu_nwu() * Eigen::Vector3d::UnitY() + Eigen::Vector3d::UnitX()).norm(), 1e-15);
  EXPECT_LT((quat_enu_nwu().toRotationMatrix() - rot_enu_nwu()).norm(), 1e-15);
}

TEST(Attitude, AngleBetweenAndHeadingInclinationDecomposition) {
  const Eigen::Quaterniond a = quat_from_euler_zyx(0.1, 0.2, 0.3);
  EXPECT_NEAR(quat_angle_between(a, Eigen::Quaterniond(-a.coeffs())), 0.0, 1e-12);
  // Pure yaw error: all heading, no inclination.
  const auto hi = heading_inclination_of_world_error(quat_from_euler_zyx(0.0, 0.0, 0.2));
  EXPECT_NEAR(hi.heading_rad, 0.2, 1e-12);
  EXPECT_NEAR(hi.inclination_rad, 0.0, 1e-7);
  // Pure roll error: all inclination.
  const auto hi2 = heading_inclination_of_world_error(quat_from_euler_zyx(0.3, 0.0, 0.0));
  EXPECT_NEAR(hi2.heading_rad, 0.0, 1e-12);
  EXPECT_NEAR(hi2.inclination_rad, 0.3, 1e-12);
}

TEST(Attitude, WrapAngle) {
  EXPECT_NEAR(wrap_angle(3.0 * kPi), kPi, 1e-12);
  EXPECT_NEAR(wrap_angle(-kPi / 2.0), -kPi / 2.0, 1e-15);
  EXPECT_NEAR(wrap_angle(2.0 * kPi + 0.1), 0.1, 1e-12);
}

TEST(TimeStep, FirstOkNonMonotonicAndGapAreTold) {
  EXPECT_EQ(time_step(5, -1, 0.5).kind, TimeStep::kFirst);
  const TimeStep ok = time_step(1'010'000'000, 1'000'000'000, 0.5);
  EXPECT_EQ(ok.kind, TimeStep::kOk);
  EXPECT_DOUBLE_EQ(ok.dt_s, 0.01);
  EXPECT_EQ(time_step(1'000'000'000, 1'000'000'000, 0.5).kind, TimeStep::kNonMonotonic);
  EXPECT_EQ(time_step(900'000'000, 1'000'000'000, 0.5).kind, TimeStep::kNonMonotonic);
  const TimeStep gap = time_step(1'600'000'000, 1'000'000'000, 0.5);
  EXPECT_EQ(gap.kind, TimeStep::kGap);
  EXPECT_NEAR(gap.dt_s, 0.6, 1e-12);
}

}  // namespace
}  // namespace poise
