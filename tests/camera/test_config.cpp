// Tag map and camera config parsing: examples in config/camera load; mistakes fail clearly.
#include "camera_test_util.h"

#include "poise/camera/pipeline.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

namespace poise::camera {
namespace {

using namespace poise::camera::testing;

constexpr double kExact = 1e-9;

template <typename F>
void expect_config_error(F&& f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "expected ConfigError containing '" << needle << "'";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(TagMap, ParsesQuaternionAndRpyEntries) {
  const TagMap m = parse_tag_map(R"(
family: tag36h11
default_size_m: 0.16
tags:
  - id: 0
    position_m: [0, 2, 1.5]
    rpy_deg: [90, 0, 0]
  - id: 5
    size_m: 0.08
    position_m: [1, 2, 1.5]
    q_world_tag: [0.7071067811865476, 0.7071067811865476, 0, 0]
)",
                                 "map.yaml");
  ASSERT_EQ(m.tags.size(), 2U);
  EXPECT_NEAR(m.find(0)->size_m, 0.16, kExact);
  EXPECT_NEAR(m.find(5)->size_m, 0.08, kExact);
  // Both describe a wall tag facing south: z_tag = -y_world.
  for (int id : {0, 5}) {
    const Eigen::Vector3d z = m.find(id)->T_world_tag.linear().col(2);
    EXPECT_LT((z - Eigen::Vector3d(0, -1, 0)).norm(), 1e-9) << "id " << id;
  }
  EXPECT_EQ(m.find(3), nullptr);
  // docs/CAMERA.md: [90, 0, 90] faces east, [90, 0, -90] west; y stays up.
  const TagMap walls = parse_tag_map(
      "tags:\n  - {id: 1, size_m: 0.1, position_m: [0,0,0], rpy_deg: [90, 0, 90]}\n"
      "  - {id: 2, size_m: 0.1, position_m: [0,0,0], rpy_deg: [90, 0, -90]}\n",
      "walls.yaml");
  EXPECT_LT((walls.find(1)->T_world_tag.linear().col(2) - Eigen::Vector3d::UnitX()).norm(), 1e-9);
  EXPECT_LT((walls.find(2)->T_world_tag.linear().col(2) + Eigen::Vector3d::UnitX()).norm(), 1e-9);
  EXPECT_LT((walls.find(1)->T_world_tag.linear().col(1) - Eigen::Vector3d::UnitZ()).norm(), 1e-9);
}

TEST(TagMap, MistakesAreClearErrors) {
  expect_config_error([] { (void)parse_tag_map("tags: []\n", "m"); }, "no tags");
  expect_config_error(
      [] { (void)parse_tag_map("tags:\n  - id: 1\n    position_m: [0,0,0]\n    rpy_deg: [0,0,0]\n", "m"); },
      "size_m missing");
  expect_config_error(
      [] {
        (void)parse_tag_map("tags:\n  - {id: 1, size_m: 0.1, position_m: [0,0,0], rpy_deg: [0,0,0]}\n"
                            "  - {id: 1, size_m: 0.1, position_m: [0,0,0], rpy_deg: [0,0,0]}\n", "m");
      },
      "duplicate id");
  expect_config_error(
      [] { (void)parse_tag_map("tags:\n  - {id: 1, size_m: 0.1, position_m: [0,0,0], q_world_tag: [1,1,0,0]}\n", "m"); },
      "expected a unit quaternion");
  expect_config_error(
      [] { (void)parse_tag_map("tags:\n  - {id: 1, size_m: 0.1, position_m: [0,0]}\n", "m"); },
      "position_m must be a list of 3");
}

TEST(CameraConfig, ExampleFilesLoad) {
  const CameraConfig c = load_camera_config(poise::testing::source_path("config/camera/camera.yaml"));
  EXPECT_EQ(c.detector.family, "tag36h11");
  const TagMap m = load_tag_map(poise::testing::source_path("config/camera/tags_example.yaml"));
  EXPECT_FALSE(m.tags.empty());
  const CameraIntrinsics ros =
      load_intrinsics(poise::testing::source_path("config/camera/intrinsics_example_ros.yaml"));
  const CameraIntrinsics cv =
      load_intrinsics(poise::testing::source_path("config/camera/intrinsics_example_opencv.yaml"));
  EXPECT_NEAR(ros.fx_px, cv.fx_px, kExact);
  EXPECT_EQ(ros.distortion, cv.distortion);
  CameraPipeline pipeline(c, ros, m);  // all consistent
  EXPECT_EQ(pipeline.config().sensor_id, c.sensor_id);
}

// Defaults in one place (issue 30): the shipped camera.yaml holds only what differs from
// CameraConfig{} (the requested resolution and rate, two detector threads); every other field of
// the loaded file is exactly the struct's default.
TEST(CameraConfig, GivenTheShippedFileWhenLoadedThenOnlyItsOverridesDifferFromTheStructDefaults) {
  const CameraConfig c = load_camera_config(poise::testing::source_path("config/camera/camera.yaml"));
  const CameraConfig d;
  // the overrides, each different from its default (a value equal to the default would restate it)
  EXPECT_EQ(c.width_px, 640);
  EXPECT_EQ(c.height_px, 480);
  EXPECT_EQ(c.fps, 30.0);
  EXPECT_EQ(c.detector.threads, 2);
  EXPECT_NE(d.width_px, 640);
  EXPECT_NE(d.height_px, 480);
  EXPECT_NE(d.fps, 30.0);
  EXPECT_NE(d.detector.threads, 2);
  // everything else: the struct's defaults
  EXPECT_EQ(c.sensor_id, d.sensor_id);
  EXPECT_EQ(c.frame_id, d.frame_id);
  EXPECT_EQ(c.capture_delay_s, d.capture_delay_s);
  EXPECT_EQ(c.max_image_pixels, d.max_image_pixels);
  EXPECT_EQ(c.detector.family, d.detector.family);
  EXPECT_EQ(c.detector.decimate, d.detector.decimate);
  EXPECT_EQ(c.detector.blur_sigma, d.detector.blur_sigma);
  EXPECT_EQ(c.detector.refine_edges, d.detector.refine_edges);
  EXPECT_EQ(c.detector.decode_sharpening, d.detector.decode_sharpening);
  EXPECT_EQ(c.detector.max_hamming, d.detector.max_hamming);
  EXPECT_EQ(c.detector.min_decision_margin, d.detector.min_decision_margin);
  EXPECT_EQ(c.tag_pose.ambiguity_ratio_max, d.tag_pose.ambiguity_ratio_max);
  EXPECT_EQ(c.tag_pose.ambiguity_min_angle_rad, d.tag_pose.ambiguity_min_angle_rad);
  EXPECT_EQ(c.tag_pose.max_reprojection_rms_px, d.tag_pose.max_reprojection_rms_px);
  EXPECT_EQ(c.world_pose.ambiguity_ratio_max, d.world_pose.ambiguity_ratio_max);
  EXPECT_EQ(c.world_pose.ambiguity_min_angle_rad, d.world_pose.ambiguity_min_angle_rad);
  EXPECT_EQ(c.world_pose.max_reprojection_rms_px, d.world_pose.max_reprojection_rms_px);
  EXPECT_EQ(c.world_pose.pixel_sigma_px, d.world_pose.pixel_sigma_px);
  EXPECT_EQ(c.world_pose.pixel_sigma_dof, d.world_pose.pixel_sigma_dof);
  EXPECT_EQ(c.world_pose.corner_noise, d.world_pose.corner_noise);
  EXPECT_EQ(c.world_pose.max_iterations, d.world_pose.max_iterations);
  EXPECT_EQ(c.unknown_tag_size_m, d.unknown_tag_size_m);
  EXPECT_FALSE(c.T_body_camera.has_value());
  // the world pose's ambiguity thresholds are the tag pose's (one default, one pair of keys)
  EXPECT_EQ(d.world_pose.ambiguity_ratio_max, d.tag_pose.ambiguity_ratio_max);
  EXPECT_EQ(d.world_pose.ambiguity_min_angle_rad, d.tag_pose.ambiguity_min_angle_rad);
}

TEST(CameraConfig, ParsesSectionsAndExtrinsic) {
  const CameraConfig c = parse_camera_config(R"(
capture: {delay_ms: 12.5}
detector: {family: tag25h9, decimate: 1.5, threads: 2, refine_edges: false}
pose: {ambiguity_ratio_max: 0.4, ambiguity_min_angle_deg: 5, corner_noise: edges}
extrinsic: {position_m: [0.05, 0, 0.02], q_body_camera: [1, 0, 0, 0]}
)",
                                             "c.yaml");
  EXPECT_NEAR(c.capture_delay_s, 0.0125, kExact);
  EXPECT_EQ(c.detector.family, "tag25h9");
  EXPECT_FALSE(c.detector.refine_edges);
  EXPECT_NEAR(c.tag_pose.ambiguity_min_angle_rad, 5 * kDeg, kExact);
  EXPECT_NEAR(c.world_pose.ambiguity_ratio_max, 0.4, kExact);
  EXPECT_EQ(c.world_pose.corner_noise, CornerNoise::kEdgeLines);
  EXPECT_EQ(CameraConfig{}.world_pose.corner_noise, CornerNoise::kWhite);
  ASSERT_TRUE(c.T_body_camera.has_value());
  EXPECT_NEAR(c.T_body_camera->translation().x(), 0.05, kExact);
}

TEST(CameraConfig, MistakesAreClearErrors) {
  expect_config_error([] { (void)parse_camera_config("detector: {decimat: 2}\n", "c.yaml"); },
                      "c.yaml: unknown key 'detector.decimat' (known: family, decimate,");
  expect_config_error([] { (void)parse_camera_config("detector: {threads: 0}\n", "c.yaml"); },
                      "threads must be in [1, 64]");
  expect_config_error([] { (void)parse_camera_config("detector: {family: tagXX}\n", "c.yaml"); },
                      "unknown tag family");
  expect_config_error([] { (void)parse_camera_config("pose: {pixel_sigma_dof: 0}\n", "c.yaml"); },
                      "pose.pixel_sigma_dof must be in (0, 1e6]");
  expect_config_error([] { (void)parse_camera_config("pose: {corner_noise: lines}\n", "c.yaml"); },
                      "c.yaml: pose.corner_noise must be edges or white (got 'lines')");
  expect_config_error(
      [] { (void)parse_camera_config("extrinsic: {position_m: [0, 0, 0]}\n", "c.yaml"); },
      "q_body_camera");
}

TEST(CameraConfig, MapFamilyMustMatchDetector) {
  CameraConfig c;
  TagMap m = map_of({tag_ahead(1, 0.16, 1.0)}, "tag25h9");
  expect_config_error([&] { CameraPipeline p(c, vga_camera(), m); }, "family tag25h9");
}

}  // namespace
}  // namespace poise::camera
