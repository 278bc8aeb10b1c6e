// libapriltag wrapper: family layouts, corner order and pixel convention against rendered truth.
#include "camera_test_util.h"

#include "poise/camera/detector.h"

#include <gtest/gtest.h>

#include <cstdio>

namespace poise::camera {
namespace {

using namespace poise::camera::testing;

constexpr double kCornerBiasTolPx = 0.1;  // mean corner offset after the library-convention fix
constexpr double kCornerRmsTolPx = 0.25;  // corner RMS error, blur 0.8 px + noise 2 grey levels

TEST(TagFamily, PatternFromCodesMatchesLibraryRendering) {
  for (const auto& name : tag_family_names()) {
    const TagFamilyLayout layout = tag_family_layout(name);
    ASSERT_GT(layout.codes.size(), 0U) << name;
    for (int id : {0, 1, static_cast<int>(layout.codes.size()) - 1}) {
      const cv::Mat ours = layout.pattern(id);
      const cv::Mat lib = apriltag_library_pattern(name, id);
      ASSERT_EQ(ours.size(), lib.size()) << name;
      EXPECT_EQ(cv::norm(ours, lib, cv::NORM_INF), 0.0) << name << " id " << id;
    }
  }
}

TEST(TagFamily, UnknownFamilyIsAClearError) {
  DetectorParams p;
  p.family = "tag99h1";
  try {
    TagDetector d(p);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("tag36h11"), std::string::npos) << e.what();
  }
}

// GIVEN tags rendered at known poses (several ids, rotations in the image, decimate 1 and 2)
// WHEN detected
// THEN the ids match and corners are the projected truth, in libapriltag's order (bottom-left
// first), in OpenCV pixel convention: no systematic offset, small RMS.
TEST(Detector, CornersMatchRenderedTruth) {
  const CameraIntrinsics k = vga_camera();
  SceneRenderer renderer(k, "tag36h11", 3);
  const Eigen::Isometry3d cam = camera_at_origin_looking_north();
  for (double decimate : {1.0, 2.0}) {
    DetectorParams p;
    p.decimate = decimate;
    TagDetector detector(p);
    Eigen::Vector2d bias = Eigen::Vector2d::Zero();
    double sq = 0.0;
    int n = 0;
    for (int i = 0; i < 6; ++i) {
      SceneTag tag = tag_ahead(10 + i, 0.16, 0.8 + 0.1 * i, (i - 3) * 8.0 * kDeg, (i % 3) * 9.0 * kDeg,
                               0.05 * (i - 2), 0.03 * (i - 3));
      // Roll the tag in its plane so the corner order is tested away from upright.
      tag.T_world_tag.linear() =
          tag.T_world_tag.linear() * Eigen::AngleAxisd(0.5 * i, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      RenderOptions o;
      o.blur_sigma_px = 0.8;
      o.noise_sigma = 2.0;
      o.seed = 77 + static_cast<uint64_t>(i);
      const cv::Mat img = renderer.render({tag}, cam, o);
      const auto detections = detector.detect(img);
      ASSERT_EQ(detections.size(), 1U) << "tag " << tag.id;
      EXPECT_EQ(detections[0].id, tag.id);
      EXPECT_EQ(detections[0].hamming, 0);
      const auto truth = renderer.project_corners(tag, cam);
      for (std::size_t c = 0; c < 4; ++c) {
        const Eigen::Vector2d e = detections[0].corners_px[c] - truth[c];
        ASSERT_LT(e.norm(), 1.0) << "corner " << c << " of tag " << tag.id << " (order wrong?)";
        bias += e;
        sq += e.squaredNorm();
        ++n;
      }
    }
    bias /= n;
    const double rms = std::sqrt(sq / n);
    std::printf("decimate %.0f: corner bias (%.3f, %.3f) px, RMS %.3f px over %d corners\n",
                decimate, bias.x(), bias.y(), rms, n);
    EXPECT_LT(bias.norm(), kCornerBiasTolPx);
    EXPECT_LT(rms, kCornerRmsTolPx);
  }
}

TEST(Detector, EmptySceneGivesNoDetections) {
  const CameraIntrinsics k = vga_camera(false);
  SceneRenderer renderer(k, "tag36h11", 1);
  RenderOptions o;
  o.noise_sigma = 3.0;
  const cv::Mat img = renderer.render({}, camera_at_origin_looking_north(), o);
  DetectorParams p;
  TagDetector detector(p);
  EXPECT_TRUE(detector.detect(img).empty());
}

TEST(Renderer, SameSeedSameImage) {
  const CameraIntrinsics k = vga_camera();
  SceneRenderer renderer(k, "tag36h11", 2);
  const SceneTag tag = tag_ahead(1, 0.16, 1.0);
  RenderOptions o;
  o.noise_sigma = 2.0;
  o.blur_sigma_px = 0.5;
  o.seed = 42;
  const cv::Mat a = renderer.render({tag}, camera_at_origin_looking_north(), o);
  const cv::Mat b = renderer.render({tag}, camera_at_origin_looking_north(), o);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  o.seed = 43;
  const cv::Mat c = renderer.render({tag}, camera_at_origin_looking_north(), o);
  EXPECT_GT(cv::norm(a, c, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace poise::camera
