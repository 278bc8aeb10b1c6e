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
    d.sources.push_back(SourceReport{});
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
  SourceReport fused;
  fused.source = "accel";
  fused.decision = SourceDecision::kFused;
  fused.innovation = Eigen::Vector3d(0.1, -0.2, 0.3);
  fused.innovation_variance = Eigen::Vector3d(1, 2, 3);
  fused.test_ratio = 0.5;
  fused.last_fused_stamp_ns = 42;
  SourceReport rejected;
  rejected.source = "mag";
  rejected.decision = SourceDecision::kRejected;
  rejected.reason = "disturbed_norm";
  rejected.rejected_count = 7;
  SourceReport missing;
  missing.source = "vision";  // never fused: last_fused_stamp_ns -1 -> 0 on the wire
  d.sources = {fused, rejected, missing};
  const msg::FilterDiagnostics m = to_diagnostics_msg(d, "id");
  ASSERT_EQ(m.sources().size(), 3U);
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

}  // namespace
}  // namespace poise::nodes
