// The camera component: pure message conversions, and GIVEN a synthetic source in a host WHEN it
// runs THEN tag_detections (every frame) and vision_pose arrive over DDS with sane content.
#include "camera_test_util.h"

#include "poise/camera/camera_msgs.h"
#include "poise/camera/camera_node.h"
#include "poise/dds/convert.h"
#include "poise/runtime/host.h"
#include "poise/testing/testing.h"

#include <poise/msg/visionPubSubTypes.h>

#include <gtest/gtest.h>

#include <mutex>
#include <vector>

namespace poise::camera {
namespace {

using namespace std::chrono_literals;
using namespace poise::camera::testing;

constexpr double kExact = 1e-12;

FrameResult sample_result() {
  FrameResult r;
  r.stamp_ns = 123456789;
  r.width_px = 640;
  r.height_px = 480;
  DetectionResult d;
  d.detection.id = 4;
  d.detection.hamming = 1;
  d.detection.decision_margin = 55.5;
  for (std::size_t c = 0; c < 4; ++c) {
    d.detection.corners_px[c] = Eigen::Vector2d(10.0 * static_cast<double>(c), 20.0 + static_cast<double>(c));
  }
  d.in_map = true;
  d.size_m = 0.16;
  d.pose_computed = true;
  d.pose.valid = true;
  d.pose.best.T_camera_tag.translation() = Eigen::Vector3d(0.1, -0.2, 1.5);
  d.pose.best.reprojection_rms_px = 0.3;
  d.pose.ambiguity_ratio = 0.05;
  r.detections.push_back(d);
  DetectionResult unknown = d;
  unknown.detection.id = 99;
  unknown.in_map = false;
  unknown.pose_computed = false;
  unknown.size_m = 0.0;
  r.detections.push_back(unknown);
  r.world.valid = true;
  r.world.T_world_camera.translation() = Eigen::Vector3d(1, 2, 3);
  r.world.covariance = Eigen::Matrix<double, 6, 6>::Identity() * 1e-4;
  r.world.covariance(0, 5) = r.world.covariance(5, 0) = 2e-5;
  r.world.reprojection_rms_px = 0.4;
  r.world.tag_ids = {4};
  return r;
}

TEST(CameraMsgs, TagDetectionsCarryEveryField) {
  const FrameResult r = sample_result();
  const msg::TagDetections m = to_tag_detections_msg(r, "cam0", "camera", "tag36h11", 7);
  EXPECT_EQ(m.header().stamp_ns(), r.stamp_ns);
  EXPECT_EQ(m.header().seq(), 7U);
  EXPECT_EQ(m.header().frame_id(), "camera");
  EXPECT_EQ(m.sensor_id(), "cam0");
  EXPECT_EQ(m.image_width_px(), 640U);
  ASSERT_EQ(m.detections().size(), 2U);
  const auto& t = m.detections()[0];
  EXPECT_EQ(t.id(), 4);
  EXPECT_EQ(t.family(), "tag36h11");
  EXPECT_EQ(t.hamming(), 1);
  EXPECT_NEAR(t.decision_margin(), 55.5, kExact);
  EXPECT_NEAR(t.corners()[3].x_px(), 30.0, kExact);
  EXPECT_NEAR(t.corners()[3].y_px(), 23.0, kExact);
  EXPECT_TRUE(t.pose_valid());
  EXPECT_NEAR(t.pose_camera_tag().position_m().z(), 1.5, kExact);
  EXPECT_NEAR(t.ambiguity_ratio(), 0.05, kExact);
  EXPECT_TRUE(t.in_map());
  EXPECT_FALSE(m.detections()[1].in_map());
  EXPECT_FALSE(m.detections()[1].pose_valid());
}

TEST(CameraMsgs, TruncatesAtTheIdlBoundAndCounts) {
  FrameResult r = sample_result();
  r.detections.resize(kMaxTagsPerMessage + 5, r.detections[0]);
  uint64_t truncated = 0;
  const auto m = to_tag_detections_msg(r, "cam0", "camera", "tag36h11", 0, &truncated);
  EXPECT_EQ(m.detections().size(), kMaxTagsPerMessage);
  EXPECT_EQ(truncated, 5U);
}

TEST(CameraMsgs, VisionPoseRoundTripsThroughTheEstimatorConversion) {
  FrameResult r = sample_result();
  const msg::VisionPose m = to_vision_pose_msg(r, "cam0", 3);
  EXPECT_EQ(m.capture_stamp_ns(), r.stamp_ns);
  EXPECT_EQ(m.header().stamp_ns(), r.stamp_ns);
  EXPECT_FALSE(m.body_valid());
  EXPECT_NEAR(m.covariance()[5], 2e-5, kExact);  // row 0, col 5 (row-major)
  EXPECT_EQ(m.tag_ids(), std::vector<int32_t>{4});
  EXPECT_FALSE(dds::body_pose_from_msg(m).has_value()) << "no extrinsic: no body pose";
  const CameraPoseMeasurement pm = dds::camera_pose_from_msg(m);
  const PoseMeasurement direct = CameraPipeline::to_measurement(r);  // the camera's, no extrinsic
  EXPECT_EQ(pm.stamp_ns, direct.stamp_ns);
  EXPECT_LT((pm.p_world_camera_m - direct.p_world_body_m).norm(), kExact);
  EXPECT_LT((pm.covariance - direct.covariance).norm(), kExact);
  // With an extrinsic, the body pose and its covariance are sent.
  r.body_valid = true;
  r.T_world_body.translation() = Eigen::Vector3d(1.1, 2, 3);
  r.covariance_body = r.world.covariance * 2.0;
  const std::optional<PoseMeasurement> body = dds::body_pose_from_msg(to_vision_pose_msg(r, "cam0", 4));
  ASSERT_TRUE(body.has_value());
  EXPECT_NEAR(body->p_world_body_m.x(), 1.1, kExact);
  EXPECT_NEAR(body->covariance(0, 0), 2e-4, kExact);
}

TEST(CameraNodeParams, MissingAndUnknownParametersAreClearErrors) {
  runtime::ComponentSpec spec;
  spec.type = "camera";
  spec.name = "camera";
  spec.origin = "host.yaml";
  spec.params = YAML::Load("{source: synthetic, tags_file: t.yaml}");
  try {
    (void)camera_node_options(spec);
    FAIL() << "expected ConfigError";
  } catch (const runtime::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("intrinsics_file"), std::string::npos) << e.what();
  }
  spec.params = YAML::Load("{source: s, intrinsics_file: i, tags_file: t, colour: red}");
  EXPECT_THROW((void)camera_node_options(spec), runtime::ConfigError);
}

// GIVEN camera parameters with a capture delay (issue 36: the camera's prior of its time offset)
// WHEN they are parsed
// THEN a delay in [0, 1000) ms is taken, NaN, negative or a second and more are refused naming the
// key, and without the key the config's capture.delay_ms stays (marked -1).
TEST(CameraNode, GivenACaptureDelayParameterWhenParsedThenInRangeIsTakenAndHostileIsRefused) {
  runtime::ComponentSpec spec;
  spec.type = "camera";
  spec.name = "camera";
  spec.origin = "host.yaml";
  spec.params = YAML::Load("{source: s, intrinsics_file: i, tags_file: t, capture_delay_ms: 12.5}");
  EXPECT_DOUBLE_EQ(camera_node_options(spec).capture_delay_ms, 12.5);
  spec.params = YAML::Load("{source: s, intrinsics_file: i, tags_file: t}");
  EXPECT_DOUBLE_EQ(camera_node_options(spec).capture_delay_ms, -1.0);
  for (const char* bad : {".nan", "-1", "1000", "1e300", ".inf"}) {
    spec.params = YAML::Load(std::string("{source: s, intrinsics_file: i, tags_file: t, capture_delay_ms: ") + bad + "}");
    try {
      (void)camera_node_options(spec);
      ADD_FAILURE() << bad << " accepted";
    } catch (const runtime::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("capture_delay_ms"), std::string::npos) << e.what();
    }
  }
}

// GIVEN a host running the camera component on the synthetic source over the example map
// WHEN it renders and processes 12 frames
// THEN 12 TagDetections arrive (4 mapped tags each) and vision poses lie on the synthetic orbit
// (1.1-2.2 m in front of the wall), stamped at capture, with a positive covariance.
TEST(CameraNode, PublishesDetectionsAndPosesOverDds) {
  auto& registry = runtime::ComponentRegistry::instance();
  if (registry.find("camera") == nullptr) {
    runtime::register_camera_component(registry);
  }
  poise::testing::DomainLease domain;
  constexpr int kFrames = 12;
  const std::string host_yaml =
      "components:\n  - type: camera\n    name: cam_test\n    params:\n"
      "      source: 'synthetic:frames=" + std::to_string(kFrames) + ",fps=10'\n"
      "      intrinsics_file: " + poise::testing::source_path("config/camera/intrinsics_example_ros.yaml") + "\n"
      "      tags_file: " + poise::testing::source_path("config/camera/tags_example.yaml") + "\n"
      "      pace: true\n";
  dds::Participant participant({domain.id(), "", "", "test"});
  std::mutex mutex;
  std::vector<msg::TagDetections> detections;
  std::vector<msg::VisionPose> poses;
  dds::Reader<msg::TagDetectionsPubSubType> det_reader(
      participant, "tag_detections",  // sensor QoS (best effort), as the writer's
      [&](const msg::TagDetections& m, const auto&) {
        std::lock_guard<std::mutex> lock(mutex);
        detections.push_back(m);
      });
  dds::Reader<msg::VisionPosePubSubType> pose_reader(
      participant, "vision_pose", [&](const msg::VisionPose& m, const auto&) {
        std::lock_guard<std::mutex> lock(mutex);
        poses.push_back(m);
      });
  runtime::Host host(runtime::parse_host(YAML::Load(host_yaml), "test", "."), domain.id());
  ASSERT_TRUE(det_reader.wait_for_writers(1, 10s));
  ASSERT_TRUE(pose_reader.wait_for_writers(1, 10s));
  host.start();
  poise::testing::wait_until(
      [&] {
        std::lock_guard<std::mutex> lock(mutex);
        return static_cast<int>(detections.size()) >= kFrames;
      },
      30s);
  host.stop();
  std::lock_guard<std::mutex> lock(mutex);
  // tag_detections is best-effort (a sensor stream): allow a lost sample on a loaded machine.
  ASSERT_GE(static_cast<int>(detections.size()), kFrames - 2);
  for (const auto& m : detections) {
    EXPECT_EQ(m.sensor_id(), "cam_test");
    EXPECT_EQ(m.detections().size(), 4U);
    for (const auto& t : m.detections()) {
      EXPECT_TRUE(t.in_map());
      EXPECT_NEAR(t.tag_size_m(), 0.16, kExact);
    }
  }
  ASSERT_GE(static_cast<int>(poses.size()), kFrames / 2);
  const Eigen::Vector3d centroid(0.0, 3.0, 1.3);  // of config/camera/tags_example.yaml
  for (const auto& p : poses) {
    const Eigen::Vector3d pos = dds::from_msg(p.pose_world_camera().position_m());
    const double range = (pos - centroid).norm();
    EXPECT_GT(range, 1.1) << pos.transpose();
    EXPECT_LT(range, 2.2) << pos.transpose();
    EXPECT_LT(pos.y(), 3.0);
    EXPECT_EQ(p.capture_stamp_ns(), p.header().stamp_ns());
    EXPECT_EQ(p.tag_ids().size(), 4U);
    for (int i = 0; i < 6; ++i) {
      EXPECT_GT(p.covariance()[static_cast<std::size_t>(i * 7)], 0.0);
    }
    EXPECT_LT(p.reprojection_rms_px(), 1.0);
  }
}

}  // namespace
}  // namespace poise::camera
