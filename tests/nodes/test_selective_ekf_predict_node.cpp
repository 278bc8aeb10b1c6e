// GIVEN the selective_ekf component's step (what its node and `poise process` run) configured with
// predict_horizon_s (issue 36: the renderer's display time) WHEN it writes its estimates for a
// constant-rate rotation THEN attitude/<name> and pose/<name> are stamped sample + horizon and
// carry the pose the same step without a horizon wrote, turned on by the rate over the horizon
// (oracle: q (x) exp(w H) with the known gyro rate), with a larger attitude covariance.
#include "node_harness.h"

#include "poise/core/attitude.h"
#include "poise/dds/convert.h"
#include "poise/nodes/register.h"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <memory>
#include <optional>
#include <string>

namespace poise::testing {
namespace {

struct Last : nodes::StepOutputs {
  std::optional<msg::AttitudeEstimate> att;
  std::optional<msg::PoseEstimate> pose_msg;
  void attitude(const msg::AttitudeEstimate& m) override { att = m; }
  void pose(const msg::PoseEstimate& m) override { pose_msg = m; }
  void altitude(const msg::AltitudeEstimate& /*m*/) override {}
  void diagnostics(const msg::FilterDiagnostics& /*m*/) override {}
};

std::unique_ptr<nodes::EstimatorStep> selective_step(const std::string& params_yaml) {
  runtime::ComponentSpec spec;
  spec.type = "selective_ekf";
  spec.name = "selective_ekf";
  spec.params = YAML::Load(params_yaml);
  spec.origin = "test";
  return nodes::make_estimator_step(spec);
}

TEST(SelectiveEkfNodePredict, GivenAHorizonWhenEstimatingAConstantRateRotationThenThePoseIsPredictedAndStampedAhead) {
  constexpr double kHorizonS = 0.02;
  const Eigen::Vector3d w(0.0, 0.0, 1.5);  // rad/s about up: the tilt stays level
  auto with = selective_step("{predict_horizon_s: 0.02}");
  auto without = selective_step("{}");
  Last a;
  Last b;
  ImuSample last;
  for (uint32_t seq = 0; seq < 300; ++seq) {
    ImuSample s = rest_sample(seq);
    s.gyro_rps = w;
    const Eigen::Quaterniond q(Eigen::AngleAxisd(w.z() * seq * 0.01, Eigen::Vector3d::UnitZ()));
    s.mag_ut = q.conjugate() * Eigen::Vector3d(0.0, 20.0, -40.0);
    ASSERT_EQ(with->step(s), without->step(s));
    with->estimate(s, a);
    without->estimate(s, b);
    last = s;
  }
  ASSERT_TRUE(a.att && b.att && a.pose_msg && b.pose_msg);
  const int64_t horizon_ns = 20'000'000;
  EXPECT_EQ(a.att->header().stamp_ns(), last.stamp_ns + horizon_ns);
  EXPECT_EQ(a.pose_msg->header().stamp_ns(), last.stamp_ns + horizon_ns);
  EXPECT_EQ(b.att->header().stamp_ns(), last.stamp_ns);
  const Eigen::Quaterniond now = dds::from_msg(b.att->q_world_body());
  const Eigen::Quaterniond analytic = now * quat_exp(w * kHorizonS);
  // tolerance: the filter's rate estimate against the exact gyro over 20 ms, deg
  constexpr double kTolDeg = 0.01;
  EXPECT_LT(quat_angle_between(dds::from_msg(a.att->q_world_body()), analytic) * kDegPerRad, kTolDeg);
  EXPECT_LT(quat_angle_between(dds::from_msg(a.pose_msg->q_world_body()), analytic) * kDegPerRad, kTolDeg);
  double trace_a = 0.0;
  double trace_b = 0.0;
  for (int i = 0; i < 3; ++i) {
    trace_a += a.att->attitude_covariance()[static_cast<size_t>(4 * i)];
    trace_b += b.att->attitude_covariance()[static_cast<size_t>(4 * i)];
  }
  EXPECT_GT(trace_a, trace_b);
}

TEST(SelectiveEkfNodePredict, GivenHostileHorizonsOrOffsetsInTheHostFileWhenLoadedThenTheyAreRefusedNamingTheKey) {
  for (const char* bad : {"{predict_horizon_s: .nan}", "{predict_horizon_s: -0.01}", "{predict_horizon_s: 1e9}",
                          "{vision_time_offset_s: .inf}", "{vision_time_offset_sigma_s: -1}",
                          "{vision_time_offset_sigma_s: .nan}"}) {
    const std::string key = YAML::Load(bad).begin()->first.as<std::string>();
    try {
      (void)selective_step(bad);
      ADD_FAILURE() << bad << " accepted";
    } catch (const runtime::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace poise::testing
