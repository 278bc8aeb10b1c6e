// Gauss-Newton started inside a magnetic disturbance (issue 31 "cold start next to a magnet"), as
// ParallelKfColdStart.*: the simulator's tour, the first sample 7 s in, at full strength of the
// magnet brought near (30, 10, -20) uT in the world on a 50 uT / 60 deg field, which leaves 5 s
// later. The dip learnt there is the magnet's. Oracles: the simulator's truth (heading error, NEES
// against the published covariance) and the heading status.
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/testing/cold_start_tour.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace poise {
namespace {

using testing::kTourColdStartS;
using testing::kTourMagnetGoneS;
using testing::kTourSettleS;
// Oracle: the same samples solved with the true field configured (a filter that never saw the
// magnet's dip); the relearnt filter's heading RMS from 2 s after the magnet must be within this
// of it, deg. (The 2 deg is not reached by either: Gauss-Newton solves each sample
// without filtering, and the tour's accelerations tilt it: 4.2 deg.)
constexpr double kSameAsTrueFieldDeg = 0.05;
constexpr double kMinInside95 = 0.85;      // the issue asks 85 %: measured 92.5 % (see the print)
constexpr double kMinDipOffDeg = 3.0;      // the dip learnt inside the magnet is this far off, deg
constexpr double kTrueDipDeg = 60.0;       // the tour's Earth field
constexpr double kDipTolDeg = 1.0;         // the relearnt dip against it, deg

TEST(GaussNewtonColdStart, GivenAStartInsideAMagnetsFieldWhenTheFieldIsCleanThenTheDipIsRelearntAndTheCovarianceCoveredTheError) {
  // GIVEN the tour from 7 s, inside the first magnet's field
  GaussNewton gn;
  GaussNewtonParams truth_params;
  truth_params.dip_deg = kTrueDipDeg;
  truth_params.field_magnitude_ut = 50.0;
  GaussNewton oracle(truth_params);
  double sq_oracle = 0.0;
  double sq = 0.0;
  int n_after = 0;
  NeesSummary nees;
  bool unverified_in_magnet = true;
  double learnt_dip_deg = 0.0;
  // WHEN it solves every sample until the attached magnet
  testing::run_tour_until_attached_magnet(kTourColdStartS, [&](const sim::SimSample& s) {
    const double t = s.truth.t_s;
    const bool oracle_ok = oracle.update(s.imu);
    if (!gn.update(s.imu) || !oracle_ok) {
      return;
    }
    if (t < kTourColdStartS + 1.0) {
      learnt_dip_deg = gn.dip_rad() * kDegPerRad;
    }
    const Eigen::Vector3d e = world_attitude_error(gn.result().q_world_body, s.truth.q_world_body);
    nees.add(attitude_nees(e, gn.attitude_covariance()));
    if (t < kTourMagnetGoneS) {
      unverified_in_magnet = unverified_in_magnet && gn.heading_status() == HeadingStatus::kUnverified;
    }
    if (t >= kTourMagnetGoneS + kTourSettleS) {
      sq += e.z() * e.z();
      const Eigen::Vector3d eo = world_attitude_error(oracle.result().q_world_body, s.truth.q_world_body);
      sq_oracle += eo.z() * eo.z();
      ++n_after;
    }
  });
  const double rms_deg = std::sqrt(sq / std::max(1, n_after)) * kDegPerRad;
  const double oracle_rms_deg = std::sqrt(sq_oracle / std::max(1, n_after)) * kDegPerRad;
  std::printf("cold start: dip learnt %.1f deg, relearnt %.2f deg (%llu); heading RMS %.3f deg (true field configured: %.3f) over %d samples "
              "from %.0f s; median NEES %.3f, %.1f %% inside the 95 %% ellipsoid\n",
              learnt_dip_deg, gn.dip_rad() * kDegPerRad, static_cast<unsigned long long>(gn.field_relearnt_count()),
              rms_deg, oracle_rms_deg, n_after, kTourMagnetGoneS + kTourSettleS, nees.median(), 100.0 * nees.fraction_inside());
  // THEN the dip learnt inside the magnet is replaced by the clean field's, the heading is within
  // the target once the magnet is gone, the covariance covered the error, and the heading was
  // unverified while the magnet's field was the reference and is verified at the end
  EXPECT_GT(std::abs(learnt_dip_deg - kTrueDipDeg), kMinDipOffDeg) << "the start learns the magnet's dip";
  EXPECT_GE(gn.field_relearnt_count(), 1U);
  EXPECT_NEAR(gn.dip_rad() * kDegPerRad, kTrueDipDeg, kDipTolDeg);
  EXPECT_NEAR(rms_deg, oracle_rms_deg, kSameAsTrueFieldDeg);
  EXPECT_GE(nees.fraction_inside(), kMinInside95);
  EXPECT_TRUE(unverified_in_magnet);
  EXPECT_EQ(gn.heading_status(), HeadingStatus::kVerified);
}

// A dip and field magnitude from the World Magnetic Model (a known location): verified from the
// first estimate, never relearnt.
TEST(GaussNewtonColdStart, GivenAConfiguredFieldWhenStartedThenTheHeadingIsVerifiedAtOnce) {
  // GIVEN the tour's field configured; WHEN the first samples are solved
  GaussNewtonParams p;
  p.dip_deg = kTrueDipDeg;
  p.field_magnitude_ut = 50.0;
  GaussNewton gn(p);
  sim::SensorSimulator simu(sim::make_scenario("tour", 200.0, 1));
  ASSERT_TRUE(gn.update(simu.next().imu));
  // THEN the heading is verified and its variance the solution's alone
  EXPECT_EQ(gn.heading_status(), HeadingStatus::kVerified);
  EXPECT_FALSE(gn.heading_unknown());
}

}  // namespace
}  // namespace poise
