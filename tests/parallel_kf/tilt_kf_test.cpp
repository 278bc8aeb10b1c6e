// TiltKf (KF1 of paper 000) in simulated time with closed-form signals.
#include "poise/parallel_kf/tilt_kf.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <random>

namespace poise {
namespace {

constexpr double kG = 9.81;
constexpr double kDt = 0.01;               // s (100 Hz, the paper's rate)
constexpr double kTiltTolDeg = 0.5;        // deg
constexpr uint32_t kSeed = 42;
constexpr double kRestS = 5.0;            // s of rest before the motion starts
constexpr double kTiltDynTolDeg = 2.0;    // deg, under 3 m/s^2 external acceleration

TEST(TiltKf, GivenStaticTiltedSensorWhenFedNoisyAccelThenUpConvergesToTruth) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  // GIVEN a sensor rolled 30 deg, at rest, with data-sheet noise
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> n_acc(0.0, 0.04);
  std::normal_distribution<double> n_gyr(0.0, 0.05 * kRadPerDeg);
  const Eigen::Quaterniond q_world_body = quat_from_euler_zyx(30.0 * kRadPerDeg, -10.0 * kRadPerDeg, 1.0);
  const Eigen::Vector3d up_true = q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
  TiltKf kf;
  EXPECT_FALSE(kf.initialized());
  kf.reset(Eigen::Vector3d::UnitZ());  // wrong start on purpose
  ASSERT_TRUE(kf.initialized());
  // WHEN 20 s of samples arrive
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d acc = kG * up_true + Eigen::Vector3d(n_acc(rng), n_acc(rng), n_acc(rng));
    const Eigen::Vector3d gyr(n_gyr(rng), n_gyr(rng), n_gyr(rng));
    ASSERT_TRUE(kf.update(gyr, acc, kDt));
  }
  // THEN the up estimate matches the truth and no external acceleration is claimed
  EXPECT_LT(angle_between_vectors(kf.up_body(), up_true) * kDegPerRad, kTiltTolDeg);
  EXPECT_LT(kf.ext_accel_body().norm(), 0.2);  // m/s^2
  EXPECT_TRUE(kf.covariance().allFinite());
  EXPECT_LT((kf.covariance() - kf.covariance().transpose()).norm(), 1e-12);
}

TEST(TiltKf, GivenRotationWithSinusoidalAccelWhenUpdatedThenTiltTracksAndAccelIsEstimated) {
  // GIVEN a sensor at rest for kRestS, then rolling at 20 deg/s about body x while shaken along body x (perpendicular to
  // gravity for this motion), both exactly consistent
  TiltKfParams p;
  p.exact_rotation = true;
  p.renormalize = true;
  TiltKf kf(p);
  const Eigen::Vector3d w(20.0 * kRadPerDeg, 0.0, 0.0);
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  kf.reset(Eigen::Vector3d::UnitZ());
  double max_err_deg = 0.0;
  double accel_err_sum = 0.0;
  double accel_sum = 0.0;
  // WHEN 10 s are processed
  for (int i = 1; i <= 1500; ++i) {
    const double t = i * kDt;
    const bool moving = t > kRestS;
    if (moving) {
      q = quat_integrate_body_rate(q, w, kDt);
    }
    const Eigen::Vector3d a_ext(moving ? 3.0 * std::sin(2.0 * kPi * 0.5 * (t - kRestS)) : 0.0, 0.0, 0.0);
    const Eigen::Vector3d up = q.conjugate() * Eigen::Vector3d::UnitZ();
    ASSERT_TRUE(kf.update(moving ? w : Eigen::Vector3d::Zero(), kG * up + a_ext, kDt));
    if (moving) {
      max_err_deg = std::max(max_err_deg, angle_between_vectors(kf.up_body(), up) * kDegPerRad);
      accel_err_sum += (kf.ext_accel_body() - a_ext).norm();
      accel_sum += a_ext.norm();
    }
  }
  // THEN the tilt stays within tolerance and the external acceleration is recovered on average
  // (a 3 m/s^2 acceleration read as gravity would tilt the estimate by up to 17 deg)
  EXPECT_LT(max_err_deg, kTiltDynTolDeg);
  // the acceleration state explains most of the external acceleration (error < half its size)
  EXPECT_LT(accel_err_sum, 0.5 * accel_sum);
  std::printf("max tilt error %.3f deg, accel error / accel = %.3f\n", max_err_deg, accel_err_sum / accel_sum);
}

TEST(TiltKf, BadInputLeavesStateUntouched) {
  TiltKf kf;
  kf.reset(Eigen::Vector3d(0.0, 0.0, 2.0));
  EXPECT_NEAR(kf.up_body().norm(), 1.0, 1e-15);
  const Eigen::Vector3d before = kf.up_body();
  const double nan = std::nan("");
  EXPECT_FALSE(kf.update(Eigen::Vector3d(nan, 0, 0), Eigen::Vector3d(0, 0, kG), kDt));
  EXPECT_FALSE(kf.update(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, nan, kG), kDt));
  EXPECT_FALSE(kf.update(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, kG), 0.0));
  EXPECT_FALSE(kf.update(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, kG), -kDt));
  EXPECT_EQ(kf.up_body(), before);
  TiltKf fresh;
  fresh.reset(Eigen::Vector3d::Zero());
  EXPECT_FALSE(fresh.initialized());
}

TEST(TiltKf, PaperFirstOrderPropagationMatchesExactForSmallSteps) {
  TiltKfParams paper;
  paper.exact_rotation = false;
  paper.renormalize = false;
  TiltKfParams exact;
  exact.exact_rotation = true;
  exact.renormalize = false;
  TiltKf a(paper);
  TiltKf b(exact);
  a.reset(Eigen::Vector3d(0.1, 0.2, 1.0));
  b.reset(Eigen::Vector3d(0.1, 0.2, 1.0));
  const Eigen::Vector3d w(0.01, 0.02, -0.01);
  ASSERT_TRUE(a.predict(w, 1e-3));
  ASSERT_TRUE(b.predict(w, 1e-3));
  EXPECT_LT((a.up_body() - b.up_body()).norm(), 1e-9);
}

}  // namespace
}  // namespace poise
