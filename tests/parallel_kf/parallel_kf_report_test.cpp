// ParallelKf::sources(): the heading update's decision for each magnetometer sample, from the
// core itself (gated, forced after mag_max_reject_s, learning, missing), never inferred outside.
#include "poise/parallel_kf/parallel_kf.h"

#include <gtest/gtest.h>

#include <cstring>

namespace poise {
namespace {

constexpr int64_t kStepNs = 10'000'000;  // 100 Hz

ImuSample rest(int i, double mag_scale) {
  ImuSample s;
  s.stamp_ns = 1'000'000'000 + i * kStepNs;
  s.accel_mps2 = Eigen::Vector3d(0, 0, 9.81);
  s.gyro_rps.setZero();
  s.mag_ut = mag_scale * Eigen::Vector3d(0, 20, -40);
  s.has_mag = true;
  return s;
}

SourceReport mag_of(const ParallelKf& kf) {
  const SourceReports r = kf.sources();
  EXPECT_EQ(r.size(), 3U);
  EXPECT_EQ(r[2].source, Source::kMag);
  return r[2];
}

TEST(ParallelKfReport, MagDecisionsFollowTheGateIncludingTheForcedCase) {
  ParallelKfParams p;
  p.mag_reacquire_s = 0.0;   // no new reference: the rejection lasts
  p.mag_max_reject_s = 1.0;  // then the magnetometer is used regardless
  p.mag_verify_s = 0.0;      // the learnt reference verified at once (not relearnt from the new field)
  p.bias_estimation = false;  // no rest detector: a field that moves at rest is the gate's to judge
  ParallelKf kf(p);
  int i = 0;
  kf.update(rest(i++, 1.0));
  EXPECT_STREQ(mag_of(kf).reason, "initialising");
  kf.update(rest(i++, 1.0));
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kNotAvailable);
  EXPECT_STREQ(mag_of(kf).reason, "learning_field");
  for (; i < 150; ++i) {  // start-up window (1 s) passes
    kf.update(rest(i, 1.0));
  }
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kFused);
  EXPECT_LT(mag_of(kf).test_ratio, 1.0);
  EXPECT_EQ(mag_of(kf).last_fused_stamp_ns, rest(i - 1, 1.0).stamp_ns);
  const int64_t last_fused = mag_of(kf).last_fused_stamp_ns;
  kf.update(rest(i++, 1.5));  // |s_M| 50 % high: outside mag_norm_tol
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kRejected);
  EXPECT_STREQ(mag_of(kf).reason, "disturbed");
  EXPECT_GT(mag_of(kf).test_ratio, 1.0);
  EXPECT_NEAR(mag_of(kf).innovation[0], 0.5 * std::sqrt(20.0 * 20 + 40 * 40), 0.5) << "uT over m";
  EXPECT_EQ(mag_of(kf).last_fused_stamp_ns, last_fused);
  for (int k = 0; k < 110; ++k) {  // 1.1 s of rejection
    kf.update(rest(i++, 1.5));
  }
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kFused) << "used again after mag_max_reject_s";
  EXPECT_STREQ(mag_of(kf).reason, "forced_after_max_reject");
  EXPECT_GT(mag_of(kf).test_ratio, 1.0) << "still outside the gate";
  EXPECT_EQ(mag_of(kf).rejected_count, kf.mag_gated_count());
}

TEST(ParallelKfReport, GivenTheSensorAtRestWhenTheFieldMovesThenTheMagSaysFieldMovedAtRest) {
  // GIVEN the default filter at rest (the rest detector needs rest_min_s), its field learnt
  ParallelKf kf;
  int i = 0;
  for (; i < 300; ++i) {
    kf.update(rest(i, 1.0));
  }
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kFused);
  // WHEN the field grows by half with the sensor still, THEN it is refused as moved at rest
  for (int k = 0; k < 100; ++k) {
    kf.update(rest(i++, 1.5));
  }
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kRejected);
  EXPECT_STREQ(mag_of(kf).reason, "field_moved_at_rest");
}

TEST(ParallelKfReport, GivenAVerifiedHeadingAtRestWhenTheFieldStaysMovedLongerThanVerifyThenTheHeadingIsUnverified) {
  // GIVEN the default filter at rest with its learnt reference verified (accepted for
  // mag_verify_s after the start-up second)
  const ParallelKfParams p;
  ParallelKf kf(p);
  int i = 0;
  const int verify_samples = static_cast<int>(p.mag_verify_s * 100.0);  // 100 Hz
  for (; i < 100 + verify_samples + 100; ++i) {
    kf.update(rest(i, 1.0));
  }
  ASSERT_EQ(kf.heading_status(), HeadingStatus::kVerified);
  // WHEN the field moves with the sensor still (refused before the gate, so the gate's own
  // rejected time does not run) for just under mag_verify_s, THEN the heading is still verified
  for (int k = 0; k < verify_samples - 10; ++k) {
    kf.update(rest(i++, 1.5));
  }
  ASSERT_STREQ(mag_of(kf).reason, "field_moved_at_rest");
  EXPECT_EQ(kf.heading_status(), HeadingStatus::kVerified);
  // and past it, no field has held the heading for mag_verify_s: unverified, as a gated stretch is
  for (int k = 0; k < 20; ++k) {
    kf.update(rest(i++, 1.5));
  }
  EXPECT_EQ(kf.heading_status(), HeadingStatus::kUnverified);
  // WHEN the Earth's field is back and used again, THEN the heading is verified again: once the
  // low-passed field (rest_filter_tau_s) is within the norm tolerance of the field before it moved
  // (which is never moved towards the magnet's), 3 time constants leave 5 % of the 22 uT step
  const int settle_samples = static_cast<int>(3.0 * p.rest_filter_tau_s * 100.0);  // 100 Hz
  for (int k = 0; k < settle_samples; ++k) {
    kf.update(rest(i++, 1.0));
  }
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kFused);
  EXPECT_EQ(kf.heading_status(), HeadingStatus::kVerified);
}

TEST(ParallelKfReport, MissingAndRejectedSamplesSayWhy) {
  ParallelKf kf;
  ImuSample s = rest(0, 1.0);
  s.has_mag = false;
  kf.update(s);
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kNotAvailable);
  EXPECT_STREQ(mag_of(kf).reason, "no_sample");
  s = rest(1, 1.0);
  s.accel_mps2.x() = std::nan("");
  EXPECT_FALSE(kf.update(s));
  for (const SourceReport& r : kf.sources()) {
    EXPECT_EQ(r.decision, SourceDecision::kRejected) << to_string(r.source);
    EXPECT_STREQ(r.reason, "non_finite_accel") << to_string(r.source);
  }
  kf.reset();
  EXPECT_EQ(mag_of(kf).decision, SourceDecision::kNotAvailable);
  EXPECT_EQ(mag_of(kf).rejected_count, 0U);
}

}  // namespace
}  // namespace poise
