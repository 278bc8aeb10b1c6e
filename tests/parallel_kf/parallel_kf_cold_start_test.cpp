// The parallel KF started inside a magnetic disturbance (issue 31 "cold start next to a magnet"):
// the simulator's tour, the filter's first sample 7 s in, at full strength of the magnet brought
// near (30, 10, -20) uT in the world on a 50 uT / 60 deg field, which leaves 5 s later. Oracles:
// the simulator's truth (the heading error), the published covariance's heading variance (it must
// cover the error all along) and the status the filter reports.
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/testing/cold_start_tour.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

namespace poise {
namespace {

using testing::kTourColdStartS;
using testing::kTourMagnetGoneS;
using testing::kTourSettleS;
constexpr double kMaxHeadingRmsDeg = 2.0;  // the target, deg
// The heading error may never exceed what the published heading sigma admits at 99.7 % for one
// degree of freedom (3 sigma): the filter must not claim to know a heading it has not verified.
constexpr double kCoverSigmas = 3.0;
constexpr double kMinStartErrorDeg = 20.0;  // the start must really be off (else nothing is tested)

TEST(ParallelKfColdStart, GivenAStartInsideAMagnetsFieldWhenTheFieldIsCleanThenTheHeadingConvergesAndItsSigmaCoveredTheErrorAllAlong) {
  ParallelKf kf;
  double max_start_err_deg = 0.0;
  double sq = 0.0;
  int n_after = 0;
  int uncovered = 0;
  int samples = 0;
  bool unverified_in_magnet = true;
  bool verified_at_end = false;
  testing::run_tour_until_attached_magnet(kTourColdStartS, [&](const sim::SimSample& s) {
    const double t = s.truth.t_s;
    if (!kf.update(s.imu)) {
      return;
    }
    const ParallelKfOutput out = kf.output();
    const Eigen::Vector3d e = world_attitude_error(out.q_world_body, s.truth.q_world_body);
    const double heading_err = std::abs(e.z());
    const double sigma = std::sqrt(kf.attitude_covariance(out)(2, 2));
    ++samples;
    uncovered += heading_err > kCoverSigmas * sigma ? 1 : 0;
    if (t < kTourColdStartS + 1.0) {
      max_start_err_deg = std::max(max_start_err_deg, heading_err * kDegPerRad);
    }
    if (t < kTourMagnetGoneS) {
      unverified_in_magnet = unverified_in_magnet && kf.heading_status() != HeadingStatus::kVerified;
    }
    if (t >= kTourMagnetGoneS + kTourSettleS) {
      sq += e.z() * e.z();
      ++n_after;
    }
    verified_at_end = kf.heading_status() == HeadingStatus::kVerified;
  });
  const double rms_deg = std::sqrt(sq / std::max(1, n_after)) * kDegPerRad;
  std::printf("cold start: first-second heading error up to %.1f deg; heading RMS %.3f deg over %d samples from "
              "%.0f s; %d of %d samples outside %.0f sigma; relearnt %llu\n",
              max_start_err_deg, rms_deg, n_after, kTourMagnetGoneS + kTourSettleS, uncovered, samples, kCoverSigmas,
              static_cast<unsigned long long>(kf.field_relearnt_count()));
  EXPECT_GT(max_start_err_deg, kMinStartErrorDeg) << "the start is inside the disturbance";
  EXPECT_TRUE(unverified_in_magnet) << "never verified while the magnet's field was the reference";
  EXPECT_LT(rms_deg, kMaxHeadingRmsDeg);
  EXPECT_EQ(uncovered, 0) << "the published heading sigma covers the error all along";
  EXPECT_GE(kf.field_relearnt_count(), 1U);
  EXPECT_TRUE(verified_at_end) << "verified once the clean field has held mag_verify_s";
}

// The same tour from its first sample: the field learnt in a clean field is still provisional when
// the magnet comes near at 5 s (accepted for 4 s of the 5 s), yet the magnet's field (78 uT, more
// than the Earth's field anywhere) must not replace it.
TEST(ParallelKfColdStart, GivenACleanStartWhenAMagnetComesBeforeTheReferenceIsVerifiedThenItIsNotLearnt) {
  ParallelKf kf;
  double sq = 0.0;
  int n = 0;
  testing::run_tour_until_attached_magnet(0.0, [&](const sim::SimSample& s) {
    if (!kf.update(s.imu) || s.truth.t_s < 1.0) {
      return;
    }
    const Eigen::Vector3d e = world_attitude_error(kf.output().q_world_body, s.truth.q_world_body);
    sq += e.z() * e.z();
    ++n;
  });
  const double rms_deg = std::sqrt(sq / std::max(1, n)) * kDegPerRad;
  std::printf("clean start: heading RMS %.3f deg over %d samples, relearnt %llu\n", rms_deg, n,
              static_cast<unsigned long long>(kf.field_relearnt_count()));
  EXPECT_EQ(kf.field_relearnt_count(), 0U);
  EXPECT_LT(rms_deg, kMaxHeadingRmsDeg);
  EXPECT_EQ(kf.heading_status(), HeadingStatus::kVerified);
}

}  // namespace
}  // namespace poise
