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
  EXPECT_EQ(m.header().frame_id(), "world");
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
    SourceReport s;
    s.source = "s" + std::to_string(i);
    s.innovation = {1, 2, 3, 4, 5, 6, 7};  // one over the bound of 6
    d.sources.push_back(s);
  }
  d.counters["a"] = 1;
  const msg::FilterDiagnostics m = to_diagnostics_msg(d, "id");
  EXPECT_EQ(m.sources().size(), 16U);
  EXPECT_EQ(m.sources()[0].innovation().size(), 6U);
  ASSERT_EQ(m.counters().size(), 2U);
  EXPECT_EQ(m.counters()[1].name(), "diagnostics_truncated");
  EXPECT_EQ(m.counters()[1].value(), 4U + 16U) << "4 sources over the bound + 16 innovations";
}

}  // namespace
}  // namespace poise::nodes
