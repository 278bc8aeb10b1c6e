#include "source_bits_oracle.h"

#include "poise/core/attitude.h"
#include "poise/nodes/reports.h"

#include <gtest/gtest.h>

#include <cmath>

namespace poise::nodes {
namespace {

TEST(AttitudeReport, MessageCarriesEulerAnglesAndDisturbanceNorm) {
  AttitudeReport r;
  r.stamp_ns = 5;
  r.seq = 9;
  r.q_world_body = quat_from_euler_zyx(0.1, -0.2, 1.3);
  r.mag_disturbance_world_ut = {3.0, 4.0, 0.0};
  r.covariance = Eigen::Matrix3d::Identity() * 1e-4;
  r.sources_fused = msg::SOURCE_GYRO | msg::SOURCE_MAG;
  const msg::AttitudeEstimate m = to_attitude_msg(r, "pkf0", "parallel_kf");
  EXPECT_EQ(m.header().stamp_ns(), 5);
  EXPECT_EQ(m.header().seq(), 9U);
  EXPECT_EQ(m.header().frame_id(), "enu_magnetic");  // no declination configured
  EXPECT_EQ(m.sensor_id(), "pkf0");
  EXPECT_EQ(m.filter_id(), "parallel_kf");
  EXPECT_NEAR(m.roll_rad(), 0.1, 1e-12);
  EXPECT_NEAR(m.pitch_rad(), -0.2, 1e-12);
  EXPECT_NEAR(m.yaw_rad(), 1.3, 1e-12);
  EXPECT_DOUBLE_EQ(m.mag_disturbance_norm_ut(), 5.0);
  EXPECT_DOUBLE_EQ(m.attitude_covariance()[0], 1e-4);
  EXPECT_DOUBLE_EQ(m.attitude_covariance()[1], 0.0);
  EXPECT_EQ(m.sources_fused(), msg::SOURCE_GYRO | msg::SOURCE_MAG);
}

TEST(DiagnosticsReport, OverlongListsAreTruncatedAndCounted) {
  DiagnosticsReport d;
  d.component = "x";
  for (int i = 0; i < 20; ++i) {
    d.sources.emplace_back(Source::kAccel);
  }
  d.counters["a"] = 1;
  const msg::FilterDiagnostics m = to_diagnostics_msg(d, "id");
  EXPECT_EQ(m.sources().size(), 16U);
  ASSERT_EQ(m.counters().size(), 2U);
  EXPECT_EQ(m.counters()[1].name(), "diagnostics_truncated");
  EXPECT_EQ(m.counters()[1].value(), 4U) << "4 sources over the bound of 16";
}

// The core's decision maps 1:1: fused / rejected with the core's reason / not available.
TEST(DiagnosticsReport, SourceDecisionsMapOneToOne) {
  DiagnosticsReport d;
  SourceReport fused(Source::kAccel);
  fused.decision = SourceDecision::kFused;
  fused.innovation = Eigen::Vector3d(0.1, -0.2, 0.3);
  fused.innovation_variance = Eigen::Vector3d(1, 2, 3);
  fused.test_ratio = 0.5;
  fused.last_fused_stamp_ns = 42;
  SourceReport rejected(Source::kMag);
  rejected.decision = SourceDecision::kRejected;
  rejected.reason = "disturbed_norm";
  rejected.rejected_count = 7;
  SourceReport missing(Source::kVisionAttitude);  // never fused: last_fused_stamp_ns -1 -> 0 on the wire
  d.sources = {fused, rejected, missing};
  const msg::FilterDiagnostics m = to_diagnostics_msg(d, "id");
  ASSERT_EQ(m.sources().size(), 3U);
  EXPECT_EQ(m.sources()[0].source(), "accel");
  EXPECT_EQ(m.sources()[1].source(), "mag");
  EXPECT_EQ(m.sources()[2].source(), "vision_attitude");
  EXPECT_TRUE(m.sources()[0].fresh());
  EXPECT_TRUE(m.sources()[0].fused());
  EXPECT_EQ(m.sources()[0].reason(), "");
  EXPECT_EQ(m.sources()[0].innovation(), (std::vector<double>{0.1, -0.2, 0.3}));
  EXPECT_EQ(m.sources()[0].innovation_variance(), (std::vector<double>{1, 2, 3}));
  EXPECT_EQ(m.sources()[0].test_ratio(), 0.5);
  EXPECT_EQ(m.sources()[0].last_fused_stamp_ns(), 42);
  EXPECT_TRUE(m.sources()[1].fresh());
  EXPECT_FALSE(m.sources()[1].fused());
  EXPECT_EQ(m.sources()[1].reason(), "disturbed_norm");
  EXPECT_EQ(m.sources()[1].rejected_count(), 7U);
  EXPECT_FALSE(m.sources()[2].fresh());
  EXPECT_FALSE(m.sources()[2].fused());
  EXPECT_EQ(m.sources()[2].reason(), "not_available");
  EXPECT_EQ(m.sources()[2].last_fused_stamp_ns(), 0);
}

// The one mapping from a typed source to the IDL's bits covers every source (the switch has no
// default: a new Source fails to compile until mapped) and agrees with the hand-written oracle.
TEST(SourceBits, GivenEverySourceThenItsBitIsTheIdlBitOfItsSensor) {
  for (std::size_t i = 0; i < static_cast<std::size_t>(Source::kCount); ++i) {
    const auto s = static_cast<Source>(i);
    const auto expected = testing::expected_source_bits().find(to_string(s));
    ASSERT_NE(expected, testing::expected_source_bits().end()) << to_string(s) << " has no oracle bit";
    EXPECT_EQ(source_bit(s), expected->second) << to_string(s);
  }
}

// Only fused reports set bits, at full or reduced weight; two rows of one sensor set its bit once.
TEST(SourceBits, GivenReportsOfOneStepThenTheFusedOnesSetTheirSensorsBits) {
  SourceReport tilt(Source::kAccelTilt);
  tilt.mark_fused(10);
  SourceReport heading(Source::kMagHeading);
  heading.mark_fused(10, "inflated");
  SourceReport mag(Source::kMag);
  mag.mark_rejected("disturbance_angle");
  SourceReport vision(Source::kVisionAttitude);
  vision.mark_not_available("no_sample");
  SourceReport rest(Source::kZeroRate);
  rest.mark_fused(10);
  const SourceReports reports = {tilt, heading, mag, vision, rest};
  EXPECT_EQ(sources_fused_bits(reports), msg::SOURCE_ACCEL | msg::SOURCE_MAG);
  EXPECT_FALSE(source_fused(reports, Source::kMag)) << "the mag report itself was rejected";
  EXPECT_TRUE(source_fused(reports, Source::kMagHeading));
  EXPECT_FALSE(source_fused(reports, Source::kGyro)) << "absent from the reports";
}

}  // namespace
}  // namespace poise::nodes
