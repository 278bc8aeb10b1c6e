// Gauss-Newton's external-acceleration covariance term (issue 31): a sensor held still in an exact
// 50 uT / 60 deg field whose accelerometer also reads a known external acceleration. Oracles: the
// geometry, worked by hand (not by the solver's code). The solution fits the field exactly and the
// up vector to the accelerometer's direction, so an east acceleration a_e tilts the accelerometer
// by theta = atan(a_e / (g + a_z)) about north, and the solution turns about the field vector
// r = (0, cos dip, -sin dip): the world error is theta (0, 1, -tan dip), a heading error
// tan(dip) theta (1.73 theta at 60 deg) that the residual does not see (the angle between the
// two vectors stays the dip to second order).
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/gauss_newton/gauss_newton.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

namespace poise {
namespace {

constexpr double kG = 9.81;             // gravity the accelerometer reads at rest, m/s^2
constexpr double kDipDeg = 60.0;        // the field's dip, deg
constexpr double kFieldUt = 50.0;       // the field's size, uT
constexpr double kRateHz = 200.0;       // samples per second
constexpr double kRestS = 10.0;         // at rest first (the norm's gravity learnt), s
constexpr double kShakeS = 20.0;        // then shaken for this long, s
constexpr double kSettleS = 1.0;        // the term's 0.5 s averages settled after this, s
constexpr double kAccelMps2 = 1.0;      // amplitude of the east and up accelerations, m/s^2
constexpr double kEastHz = 1.3;         // their frequencies (incommensurate: every phase pair occurs), Hz
constexpr double kUpHz = 0.9;
// The solution's error against the hand-worked (first-order) one, relative to its size: second
// order in the turn about the field, theta / cos(dip) <= 13 deg here, (0.23 rad)^2 / 2 = 2.6 %;
// plus an absolute floor for the instants theta crosses zero, rad.
constexpr double kGeometryRelTol = 0.05;
constexpr double kGeometryAbsTolRad = 0.01 * kRadPerDeg;
constexpr double kMinInside = 0.95;      // of the shaken samples inside the 95 % ellipsoid (kNees95Dof3)
constexpr double kMinSigmaRatio = 1.0;   // reported heading sigma over the RMS heading error
constexpr double kMaxInsideLeastSquaresOnly = 0.5;  // the residual's term alone: most samples outside

// q_world_body of the still sensor: turned and tilted, so no axis is special
Eigen::Quaterniond still_attitude() {
  return quat_from_euler_zyx(35.0 * kRadPerDeg, 10.0 * kRadPerDeg, -7.0 * kRadPerDeg);
}

ImuSample sample_at(double t_s, const Eigen::Vector3d& a_ext_world) {
  const double dip = kDipDeg * kRadPerDeg;
  const Eigen::Quaterniond q = still_attitude();
  ImuSample s;
  s.stamp_ns = static_cast<int64_t>(std::llround(t_s * 1e9));
  s.accel_mps2 = q.conjugate() * (Eigen::Vector3d(0.0, 0.0, kG) + a_ext_world);  // specific force
  s.mag_ut = q.conjugate() * (kFieldUt * Eigen::Vector3d(0.0, std::cos(dip), -std::sin(dip)));
  s.has_mag = true;
  return s;
}

TEST(GaussNewtonExternalAccel, GivenALevelSensorFacingNorthThenTheAccelSensitivityIsTheHandWorkedTiltAndHeadingCoupling) {
  // GIVEN a level sensor facing north (body = world) in the 60 deg field, unit weights
  const double dip = kDipDeg * kRadPerDeg;
  const Eigen::Vector3d u = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d r(0.0, std::cos(dip), -std::sin(dip));
  const Eigen::Matrix3d jtj = 2.0 * Eigen::Matrix3d::Identity() - u * u.transpose() - r * r.transpose();
  // WHEN the sensitivity to the accelerometer's direction is taken
  const Eigen::Matrix3d s = accel_direction_sensitivity(jtj, u);
  // THEN about east half the accelerometer's tilt (the field's rows take the other half), about
  // north all of it, and the heading tan(dip) times the north tilt, opposite in sign (by hand:
  // (J^T J)^-1 = diag(1/2, [[1, -tan], [-tan, (1 + sin^2) / cos^2]]), times diag(1, 1, 0), times it)
  const double t = std::tan(dip);
  Eigen::Matrix3d expected;
  expected << 0.25, 0.0, 0.0, 0.0, 1.0, -t, 0.0, -t, t * t;
  EXPECT_LT((s - expected).cwiseAbs().maxCoeff(), 1e-12) << s;
}

TEST(GaussNewtonExternalAccel, GivenAStillSensorShakenEastAndUpWhenSolvedThenTheHeadingErrorIsTanDipTimesTheTiltAndTheCovarianceCoversIt) {
  // GIVEN the field configured (verified from the start) and the sensor at rest, then shaken
  GaussNewtonParams p;
  p.dip_deg = kDipDeg;
  p.field_magnitude_ut = kFieldUt;
  GaussNewton gn(p);
  const double tan_dip = std::tan(kDipDeg * kRadPerDeg);
  const int n = static_cast<int>((kRestS + kShakeS) * kRateHz);
  NeesSummary nees;
  NeesSummary nees_least_squares_only;  // without the term: the residual alone
  double sq_heading = 0.0;
  double sum_var_heading = 0.0;
  int shaken = 0;
  double worst_geometry_rad = 0.0;
  double largest_tilt_rad = 0.0;
  for (int i = 0; i < n; ++i) {
    const double t = i / kRateHz;
    const double ts = t - kRestS;
    const Eigen::Vector3d a_ext = ts < 0.0 ? Eigen::Vector3d::Zero()
                                           : Eigen::Vector3d(kAccelMps2 * std::sin(2.0 * kPi * kEastHz * ts), 0.0,
                                                             kAccelMps2 * std::sin(2.0 * kPi * kUpHz * ts + 0.7));
    // WHEN every sample is solved
    ASSERT_TRUE(gn.update(sample_at(t, a_ext))) << t;
    if (ts < kSettleS) {
      continue;
    }
    const Eigen::Vector3d e = world_attitude_error(gn.result().q_world_body, still_attitude());
    const double theta = std::atan2(a_ext.x(), kG + a_ext.z());
    const Eigen::Vector3d e_hand = theta * Eigen::Vector3d(0.0, 1.0, -tan_dip);
    // the error's sign convention (q_true q_est^-1) against the rotation's: compare magnitudes and
    // the heading's sign against the north tilt's
    const double off_rad = std::max({std::abs(std::abs(e.y()) - std::abs(e_hand.y())),
                                     std::abs(std::abs(e.z()) - std::abs(e_hand.z())), std::abs(e.x())});
    EXPECT_LE(off_rad, kGeometryRelTol * e_hand.norm() + kGeometryAbsTolRad) << "t " << t;
    worst_geometry_rad = std::max(worst_geometry_rad, off_rad);
    if (std::abs(theta) > 0.5 * kRadPerDeg) {
      EXPECT_LT(e.y() * e.z(), 0.0) << "heading turns against the north tilt, t " << t;
    }
    largest_tilt_rad = std::max(largest_tilt_rad, std::abs(theta));
    const Eigen::Matrix3d cov = gn.attitude_covariance();
    nees.add(attitude_nees(e, cov));
    const Eigen::Matrix3d r = gn.result().q_world_body.toRotationMatrix();
    const Eigen::Matrix3d ls = r * (std::max(gn.state().residual2_lp, kMinResidualVar) *
                                    gn.result().information_body.inverse()) * r.transpose();
    nees_least_squares_only.add(attitude_nees(e, ls));
    sq_heading += e.z() * e.z();
    sum_var_heading += cov(2, 2);
    ++shaken;
  }
  const double rms_heading = std::sqrt(sq_heading / shaken);
  const double sigma_heading = std::sqrt(sum_var_heading / shaken);
  std::printf("shaken +-%.1f m/s^2 east and up: largest tilt %.2f deg, heading error RMS %.2f deg (tan(dip) %.2f), "
              "reported heading sigma (RMS) %.2f deg; median NEES %.2f, %.1f %% inside the 95 %% ellipsoid "
              "(least-squares term alone: median %.3g, %.1f %%); geometry off by at most %.3f deg\n",
              kAccelMps2, largest_tilt_rad * kDegPerRad, rms_heading * kDegPerRad, tan_dip,
              sigma_heading * kDegPerRad, nees.median(), 100.0 * nees.fraction_inside(),
              nees_least_squares_only.median(), 100.0 * nees_least_squares_only.fraction_inside(),
              worst_geometry_rad * kDegPerRad);
  // THEN the error is the hand-worked turn about the field (heading = tan(dip) x the north tilt),
  // checked at every sample above; AND the published covariance covers it, where the residual alone does not
  EXPECT_GE(nees.fraction_inside(), kMinInside);
  EXPECT_GE(sigma_heading / rms_heading, kMinSigmaRatio);
  EXPECT_LT(nees_least_squares_only.fraction_inside(), kMaxInsideLeastSquaresOnly) << "the residual does not see it";
}

}  // namespace
}  // namespace poise
