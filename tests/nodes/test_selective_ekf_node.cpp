// GIVEN the selective EKF node running in a host on its own domain, fed a simulated handheld motion
// over DDS with tag poses for the first seconds WHEN the tag poses stop arriving THEN its published
// attitude keeps the IMU-only quality: the same as its core given the same inputs directly, and
// no worse than the core that never saw a tag (issue 21: the camera gone for minutes).
#include "node_harness.h"

#include "poise/selective_ekf/selective_ekf.h"
#include "poise/sim/sensor_simulator.h"

#include <poise/msg/visionPubSubTypes.h>

#include <cmath>
#include <vector>

namespace poise::testing {
namespace {

using sim::make_scenario;
using sim::SensorSimulator;
using sim::SimConfig;
using sim::SimSample;
using sim::Truth;

constexpr double kRateHz = 100.0;
constexpr double kVisionUntilS = 10.0;     // tag poses at 33 Hz until then, none after
constexpr double kScoredFromS = 15.0;      // the blackout is scored from here to the end
constexpr double kDurationS = 40.0;        // 30 s without a tag pose
/// The node and its core given the same inputs directly differ only by when the late poses
/// arrived (the core replays them at their capture stamps; the output glides to the state).
constexpr double kSameAsCoreDeg = 0.01;
/// The node after the tag is lost against the core that never saw one (both IMU only then): the
/// node may keep a better gyro bias from the vision period, never a worse attitude.
constexpr double kImuOnlyMarginDeg = 0.05;

/// The camera pose of a tag detection at the truth (identity extrinsic, 1 cm / ~1 deg covariance).
msg::VisionPose vision_from_truth(const Truth& t, uint32_t seq) {
  msg::VisionPose v;
  v.header(dds::make_header(t.stamp_ns, seq, "world"));
  v.sensor_id("cam");
  v.capture_stamp_ns(t.stamp_ns);
  msg::Pose camera;
  camera.position_m(dds::to_msg(t.p_world_m));
  camera.orientation(dds::to_msg(t.q_world_body));
  v.pose_world_camera(camera);
  v.body_valid(false);
  Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Zero();
  cov.diagonal() << 1e-4, 1e-4, 1e-4, 3e-4, 3e-4, 3e-4;
  dds::to_array(cov, v.covariance());
  return v;
}

double rms(const std::vector<double>& e) {
  double s = 0.0;
  for (double x : e) {
    s += x * x;
  }
  return e.empty() ? std::nan("") : std::sqrt(s / static_cast<double>(e.size()));
}

TEST(SelectiveEkfNode, GivenTheTagPosesStopWhenRunningThenTheAttitudeKeepsTheImuOnlyQuality) {
  NodeHarness h("{type: selective_ekf, name: sekf}", "attitude/selective_ekf");
  dds::Writer<msg::VisionPosePubSubType> vision(h.participant(), "vision_pose", dds::QosKind::kEstimate);
  ASSERT_TRUE(h.connected());
  ASSERT_TRUE(vision.wait_for_readers(1, std::chrono::seconds(10)));

  SimConfig cfg = make_scenario("random_motion", kRateHz, 21);
  cfg.duration_s = kDurationS;
  cfg.magnets.clear();  // the IMU-only quality of an undisturbed room
  SensorSimulator sim(cfg);
  SelectiveEkf same;      // the node's inputs, in order
  SelectiveEkf imu_only;  // never a tag
  std::vector<Truth> truth;
  std::vector<Eigen::Quaterniond> q_same;
  std::vector<Eigen::Quaterniond> q_imu_only;
  uint32_t seq = 0;
  while (!sim.done()) {
    SimSample s = sim.next();
    s.imu.seq = seq;
    h.publish(s.imu);
    same.update_imu(s.imu);
    imu_only.update_imu(s.imu);
    if (s.truth.t_s < kVisionUntilS && seq % 3 == 0) {
      const msg::VisionPose v = vision_from_truth(s.truth, seq);
      vision.write(v);
      same.update_vision(to_vision_pose(dds::camera_pose_from_msg(v)));
    }
    truth.push_back(s.truth);
    q_same.push_back(same.q_world_body());
    q_imu_only.push_back(imu_only.q_world_body());
    ++seq;
  }
  // the node's estimate of the last sample (bounded wait)
  ASSERT_TRUE(wait_until([&] { return h.attitude(seq - 1).has_value(); }, std::chrono::seconds(10)));

  std::vector<double> e_node;
  std::vector<double> e_same;
  std::vector<double> e_imu_only;
  size_t missing = 0;
  for (uint32_t k = 0; k < seq; ++k) {
    if (truth[k].t_s < kScoredFromS) {
      continue;
    }
    const auto att = h.attitude(k);
    if (!att) {
      ++missing;  // best-effort input: a dropped sample has no estimate
      continue;
    }
    const Eigen::Quaterniond q_node = dds::from_msg(att->q_world_body());
    e_node.push_back(quat_angle_between(q_node, truth[k].q_world_body) * kDegPerRad);
    e_same.push_back(quat_angle_between(q_same[k], truth[k].q_world_body) * kDegPerRad);
    e_imu_only.push_back(quat_angle_between(q_imu_only[k], truth[k].q_world_body) * kDegPerRad);
    EXPECT_NEAR(quat_angle_between(q_node, q_same[k]) * kDegPerRad, 0.0, kSameAsCoreDeg) << "seq " << k;
  }
  ASSERT_EQ(missing, 0u) << "samples lost on loopback: the comparison with the core needs every one";
  const double node_rms = rms(e_node);
  const double imu_only_rms = rms(e_imu_only);
  std::printf("blackout %.0f-%.0f s: node %.3f deg RMS, same core %.3f, IMU-only core %.3f\n", kScoredFromS,
              kDurationS, node_rms, rms(e_same), imu_only_rms);
  EXPECT_LE(node_rms, imu_only_rms + kImuOnlyMarginDeg);
}

}  // namespace
}  // namespace poise::testing
