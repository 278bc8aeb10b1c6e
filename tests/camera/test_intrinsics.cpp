// Intrinsics files: OpenCV and ROS formats load; missing/zero/inconsistent values fail clearly.
#include "camera_test_util.h"

#include <gtest/gtest.h>

#include <opencv2/core/persistence.hpp>

#include <cstdio>
#include <fstream>
#include <string>

namespace poise::camera {
namespace {

constexpr double kExact = 1e-12;

std::string temp_path(const std::string& name) {
  return ::testing::TempDir() + "poise_cam_" + name;
}

std::string ros_yaml(const std::string& k_data, const std::string& extra = "") {
  return "image_width: 640\nimage_height: 480\ncamera_name: test\ncamera_matrix:\n  rows: 3\n"
         "  cols: 3\n  data: [" + k_data + "]\ndistortion_model: plumb_bob\n"
         "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [-0.1, 0.02, 0.001, 0.0, 0.0]\n" +
         extra;
}

void expect_error_containing(const std::string& text, const std::string& needle) {
  try {
    (void)parse_intrinsics(text, "test.yaml");
    ADD_FAILURE() << "expected ConfigError containing '" << needle << "'";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("test.yaml"), std::string::npos) << e.what();
  }
}

TEST(Intrinsics, LoadsOpenCvCalibrationFile) {
  const std::string path = temp_path("opencv.yaml");
  {
    cv::FileStorage fs(path, cv::FileStorage::WRITE);
    fs << "image_width" << 640 << "image_height" << 480;
    fs << "camera_matrix" << cv::Mat(cv::Matx33d(500, 0, 320.5, 0, 501, 240.25, 0, 0, 1));
    fs << "distortion_coefficients" << cv::Mat(cv::Matx<double, 1, 5>(-0.1, 0.02, 0.001, 0.0, 0.003));
  }
  const CameraIntrinsics k = load_intrinsics(path);
  EXPECT_EQ(k.width_px, 640);
  EXPECT_EQ(k.height_px, 480);
  EXPECT_NEAR(k.fx_px, 500.0, kExact);
  EXPECT_NEAR(k.fy_px, 501.0, kExact);
  EXPECT_NEAR(k.cx_px, 320.5, kExact);
  EXPECT_NEAR(k.cy_px, 240.25, kExact);
  ASSERT_EQ(k.distortion.size(), 5U);
  EXPECT_NEAR(k.distortion[4], 0.003, kExact);
  std::remove(path.c_str());
}

TEST(Intrinsics, LoadsRosCameraInfoAndRoundTrips) {
  const CameraIntrinsics k = parse_intrinsics(ros_yaml("500, 0, 320, 0, 502, 240, 0, 0, 1"), "ros");
  EXPECT_NEAR(k.fy_px, 502.0, kExact);
  EXPECT_NEAR(k.distortion[0], -0.1, kExact);
  const CameraIntrinsics again = parse_intrinsics(to_ros_camera_info_yaml(k), "roundtrip");
  EXPECT_NEAR(again.fx_px, k.fx_px, kExact);
  EXPECT_NEAR(again.cy_px, k.cy_px, kExact);
  EXPECT_EQ(again.distortion, k.distortion);
}

TEST(Intrinsics, GivenAnOpenCvMatrixDeclaringHugeRowsWhenParsedThenAClearErrorInsteadOfAnAllocation) {
  // GIVEN an OpenCV calibration file whose camera_matrix declares rows: 3221225472 (found by
  // fuzz_config: OpenCV allocated rows x cols, 48 GB, before reading the data)
  const std::string text =
      "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
      "   rows: 3221225472\n   cols: 3\n   dt: d\n   data: [ 500.0, 0., 320., 0., 500.0, 240., 0., 0., 1. ]\n";
  // WHEN parsed THEN the error names the file and the key
  expect_error_containing(text, "'camera_matrix.rows' must be an integer in [0, 16]");
  std::string big_cols = text;
  big_cols.replace(big_cols.find("rows: 3221225472"), 16, "rows: 3");
  big_cols.replace(big_cols.find("cols: 3"), 7, "cols: 100000");
  expect_error_containing(big_cols, "'camera_matrix.cols' must be an integer in [0, 16]");
}

TEST(Intrinsics, GivenAHostileOpenCvFileWhenParsedThenEachFlawIsAClearErrorNamingIt) {
  const std::string good =
      "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
      "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 500.0, 0., 320., 0., 500.0, 240., 0., 0., 1. ]\n";
  EXPECT_NEAR(parse_intrinsics(good, "good").fx_px, 500.0, kExact);
  auto with = [&good](const std::string& from, const std::string& to) {
    std::string t = good;
    t.replace(t.find(from), from.size(), to);
    return t;
  };
  expect_error_containing(with("image_height: 480\n", "image_height: 480\nimage_width: 320\n"),
                          "key 'image_width' is given twice");
  expect_error_containing(with("0., 0., 1. ]", ".nan, 0., 1. ]"), "camera_matrix.data[6]");  // bare .nan refused
  expect_error_containing(with("0., 0., 1. ]", "\".nan\", 0., 1. ]"), "not of the form");  // must-be-zero entry
  expect_error_containing(with("500.0, 0., 320.", "1e308, 0., 320."), "fx/fy");
  expect_error_containing(with("0., 0., 1. ]", "0., 1. ]"), "declares 3x3 but has 8 values");
  expect_error_containing(with("   data: [", "   data: {a: 1}\n   other: ["), "has no 'data' list");
}

TEST(Intrinsics, ZeroFocalLengthIsAClearError) {
  expect_error_containing(ros_yaml("0, 0, 320, 0, 0, 240, 0, 0, 1"), "focal lengths must be positive");
}

TEST(Intrinsics, MissingCameraMatrixIsAClearError) {
  expect_error_containing("image_width: 640\nimage_height: 480\n", "missing 'camera_matrix'");
}

TEST(Intrinsics, PrincipalPointOutsideImageIsAClearError) {
  expect_error_containing(ros_yaml("500, 0, 1280, 0, 500, 240, 0, 0, 1"), "outside the 640x480");
}

TEST(Intrinsics, MissingResolutionIsAClearError) {
  expect_error_containing(
      "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [500, 0, 320, 0, 500, 240, 0, 0, 1]\n",
      "image_width/image_height missing");
}

TEST(Intrinsics, WrongValueCountAndTransposedMatrixAreClearErrors) {
  expect_error_containing(ros_yaml("500, 0, 320, 0, 500, 240, 0, 0"), "declares 9 values but has 8");
  expect_error_containing(ros_yaml("500, 0, 0, 0, 500, 0, 320, 240, 1"), "not of the form");
}

TEST(Intrinsics, UnsupportedDistortionModelIsAClearError) {
  std::string text = ros_yaml("500, 0, 320, 0, 500, 240, 0, 0, 1");
  text.replace(text.find("plumb_bob"), 9, "equidistant");
  expect_error_containing(text, "not supported");
}

TEST(Intrinsics, MissingFileNamesThePath) {
  try {
    (void)load_intrinsics("/nonexistent/cam.yaml");
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/cam.yaml"), std::string::npos);
  }
}

}  // namespace
}  // namespace poise::camera
