// Capture sources: image lists with unreadable files, missing devices, injected clock stamps,
// the synthetic source, and frame-size mismatches.
#include "camera_test_util.h"

#include "poise/camera/capture.h"
#include "poise/testing/testing.h"
#include "poise/camera/pipeline.h"

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <filesystem>
#include <fstream>

namespace poise::camera {
namespace {

using namespace poise::camera::testing;
namespace fs = std::filesystem;

constexpr int64_t kNowNs = 5'000'000'000;
constexpr int64_t kDelayNs = 15'000'000;

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("poise_cam_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// GIVEN a directory with a good image and a corrupt one
// WHEN it is read as a source with an injected clock and a configured delay
// THEN the good one comes stamped now - delay, the corrupt one is skipped with its name, then end.
TEST(Capture, ImageDirectorySkipsUnreadableWithClearMessage) {
  const fs::path dir = fresh_dir("images");
  SceneRenderer renderer(vga_camera(false), "tag36h11", 1);
  cv::imwrite((dir / "a.png").string(),
              renderer.render({tag_ahead(1, 0.16, 1.0)}, camera_at_origin_looking_north(), {}));
  std::ofstream(dir / "b.png") << "this is not a png";
  SourceOptions o;
  o.clock = [] { return kNowNs; };
  o.delay_ns = kDelayNs;
  auto source = open_source(dir.string(), o);
  Frame f;
  std::string error;
  ASSERT_EQ(source->grab(f, error), GrabStatus::kFrame);
  EXPECT_EQ(f.stamp_ns, kNowNs - kDelayNs);
  EXPECT_FALSE(f.stamp_from_driver);
  EXPECT_EQ(f.image.type(), CV_8UC1);
  ASSERT_EQ(source->grab(f, error), GrabStatus::kSkipped);
  EXPECT_NE(error.find("b.png"), std::string::npos) << error;
  EXPECT_NE(error.find("cannot read image"), std::string::npos) << error;
  EXPECT_EQ(source->grab(f, error), GrabStatus::kEnd);
  // A glob over the same directory finds both, sorted.
  const auto files = expand_image_spec((dir / "*.png").string());
  ASSERT_EQ(files.size(), 2U);
  EXPECT_LT(files[0], files[1]);
}

// GIVEN a 3-frame MJPG video at 10 fps
// WHEN read as a source
// THEN frames come in order, stamped first-grab host time (minus delay) + media time, then end.
TEST(Capture, VideoFileStampsFollowMediaTime) {
  const fs::path dir = fresh_dir("video");
  const std::string path = (dir / "clip.avi").string();
  {
    cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0, cv::Size(64, 48), false);
    if (!writer.isOpened()) {
      POISE_SKIP("this OpenCV build cannot write MJPG/AVI");
    }
    for (int i = 0; i < 3; ++i) {
      writer.write(cv::Mat(48, 64, CV_8UC1, cv::Scalar(40 * (i + 1))));
    }
  }
  SourceOptions o;
  int64_t now = kNowNs;
  o.clock = [&now] { return now; };
  o.delay_ns = kDelayNs;
  auto source = open_source(path, o);
  Frame f;
  std::string error;
  std::vector<int64_t> stamps;
  while (source->grab(f, error) == GrabStatus::kFrame) {
    stamps.push_back(f.stamp_ns);
    now += 1'000'000'000;  // host time runs on; stamps must follow the media time instead
  }
  ASSERT_EQ(stamps.size(), 3U);
  constexpr int64_t kFramePeriodNs = 100'000'000;
  constexpr int64_t kStampTolNs = 1'000'000;  // media time is rounded to ms by some backends
  EXPECT_EQ(stamps[0], kNowNs - kDelayNs);
  EXPECT_NEAR(static_cast<double>(stamps[2] - stamps[0]), 2.0 * kFramePeriodNs, kStampTolNs);
}

TEST(Capture, MissingDeviceIsAClearError) {
  try {
    (void)open_source("/dev/video97", SourceOptions{});
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/video97 does not exist"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)open_source("v4l2:97", SourceOptions{}), ConfigError);
}

TEST(Capture, MissingPathAndEmptyGlobAreClearErrors) {
  EXPECT_THROW((void)open_source("/nonexistent/dir", SourceOptions{}), ConfigError);
  EXPECT_THROW((void)open_source("/nonexistent/*.png", SourceOptions{}), ConfigError);
  EXPECT_THROW((void)open_source("synthetic", SourceOptions{}), ConfigError);  // no scene
  EXPECT_THROW((void)open_source("file:/nonexistent.mp4", SourceOptions{}), ConfigError);
}

// GIVEN the synthetic source over a two-tag map
// WHEN frames are grabbed twice with the same seed
// THEN images are identical, truth poses are attached and the frame count is honoured.
TEST(Capture, SyntheticSourceIsDeterministicAndCarriesTruth) {
  SyntheticScene scene;
  scene.intrinsics = vga_camera();
  scene.tags = {tag_ahead(1, 0.16, 1.5, 0.0, 0.0, -0.2, 0.0), tag_ahead(2, 0.16, 1.5, 0.0, 0.0, 0.2, 0.0)};
  SourceOptions o;
  o.scene = scene;
  o.clock = [] { return kNowNs; };
  auto a = open_source("synthetic:frames=2,seed=3,noise=2", o);
  auto b = open_source("synthetic:frames=2,seed=3,noise=2", o);
  Frame fa;
  Frame fb;
  std::string error;
  for (int i = 0; i < 2; ++i) {
    ASSERT_EQ(a->grab(fa, error), GrabStatus::kFrame);
    ASSERT_EQ(b->grab(fb, error), GrabStatus::kFrame);
    EXPECT_EQ(cv::norm(fa.image, fb.image, cv::NORM_INF), 0.0);
    ASSERT_TRUE(fa.truth_T_world_camera.has_value());
  }
  EXPECT_EQ(a->grab(fa, error), GrabStatus::kEnd);
  EXPECT_THROW((void)open_source("synthetic:frames=x", o), ConfigError);
  EXPECT_THROW((void)open_source("synthetic:colour=red", o), ConfigError);
}

TEST(Capture, FrameSizeDifferentFromCalibrationIsAClearError) {
  CameraConfig c;
  CameraPipeline pipeline(c, vga_camera(), map_of({tag_ahead(1, 0.16, 1.0)}));
  Frame f;
  f.image = cv::Mat(720, 1280, CV_8UC1, cv::Scalar(128));
  try {
    (void)pipeline.process(f);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("1280x720 but the intrinsics are for 640x480"),
              std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace poise::camera
