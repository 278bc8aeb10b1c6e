// Image files are hostile (issue 19, item 5): sizes are read from the header and checked before
// decoding; images too small for libapriltag never reach it. Oracle: the dimensions written.
#include "poise/camera/detector.h"
#include "poise/camera/image_file.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace poise::camera {
namespace {

namespace fs = std::filesystem;

std::string temp(const std::string& name) { return (fs::path(::testing::TempDir()) / name).string(); }

void write_bytes(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()),
                                              static_cast<std::streamsize>(bytes.size()));
}

TEST(ImageHeader, GivenImagesWrittenByOpenCvWhenTheHeaderIsReadThenTheDimensionsAreTheWrittenOnes) {
  const cv::Mat img(37, 53, CV_8UC1, cv::Scalar(128));  // 53 wide, 37 high
  for (const char* ext : {".png", ".jpg", ".bmp", ".pgm", ".tiff", ".webp"}) {
    if (!cv::haveImageWriter(std::string("x") + ext)) continue;
    const std::string path = temp(std::string("hdr") + ext);
    ASSERT_TRUE(cv::imwrite(path, img)) << ext;
    const ImageHeader h = read_image_header(path);
    EXPECT_FALSE(h.format.empty()) << ext;
    EXPECT_EQ(h.width, 53) << ext;
    EXPECT_EQ(h.height, 37) << ext;
  }
  write_bytes(temp("short.png"), {0x89, 'P', 'N', 'G'});
  EXPECT_TRUE(read_image_header(temp("short.png")).format.empty());
  write_bytes(temp("text.png"), {'h', 'e', 'l', 'l', 'o'});
  EXPECT_TRUE(read_image_header(temp("text.png")).format.empty());
}

// A 200-byte JPEG that declares 30000 x 30000 px (900 MP): refused from its header.
std::vector<unsigned char> forged_jpeg(unsigned width, unsigned height) {
  std::vector<unsigned char> b = {0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x10, 'J', 'F', 'I', 'F', 0, 1, 1, 0, 0, 1, 0, 1, 0, 0};
  const std::vector<unsigned char> sof = {0xFF, 0xC0, 0x00, 0x11, 8,
                                          static_cast<unsigned char>(height >> 8), static_cast<unsigned char>(height),
                                          static_cast<unsigned char>(width >> 8), static_cast<unsigned char>(width),
                                          3, 1, 0x22, 0, 2, 0x11, 1, 3, 0x11, 1};
  b.insert(b.end(), sof.begin(), sof.end());
  b.resize(200, 0);
  b.push_back(0xFF);
  b.push_back(0xD9);
  return b;
}

TEST(ImageLimits, GivenAJpegDeclaring30000x30000WhenReadThenRefusedFromTheHeaderWithoutDecoding) {
  const std::string path = temp("bomb.jpg");
  write_bytes(path, forged_jpeg(30000, 30000));
  const ImageHeader h = read_image_header(path);
  EXPECT_EQ(h.format, "jpeg");
  EXPECT_EQ(h.width, 30000);
  EXPECT_EQ(h.height, 30000);
  std::string error;
  const cv::Mat m = read_gray_image(path, ImageLimits{}, error);
  EXPECT_TRUE(m.empty());
  EXPECT_NE(error.find(path), std::string::npos) << error;
  EXPECT_NE(error.find("jpeg 30000x30000 px exceeds the maximum of 40000000 pixels"), std::string::npos) << error;
  ImageLimits narrow;  // the side limit
  narrow.max_side_px = 20000;
  (void)read_gray_image(path, narrow, error);
  EXPECT_NE(error.find("30000x30000 px exceeds the 20000 px maximum side"), std::string::npos) << error;
}

TEST(ImageLimits, GivenImagesTooSmallForATagWhenReadOrDetectedThenRefusedNeverCrashing) {
  TagDetector detector(DetectorParams{});  // tag36h11 (10 cells), decimate 2 -> 20 px
  EXPECT_EQ(detector.min_image_side_px(), 20);
  ImageLimits limits;
  limits.min_side_px = detector.min_image_side_px();
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{{1, 1}, {2, 2}, {640, 2}, {2, 480}, {19, 400}}) {
    const cv::Mat tiny(h, w, CV_8UC1, cv::Scalar(255));
    const std::string path = temp("tiny_" + std::to_string(w) + "x" + std::to_string(h) + ".png");
    ASSERT_TRUE(cv::imwrite(path, tiny));
    std::string error;
    EXPECT_TRUE(read_gray_image(path, limits, error).empty());
    EXPECT_NE(error.find("is below the 20 px minimum side"), std::string::npos) << error;
    EXPECT_THROW((void)detector.detect(tiny), std::invalid_argument) << w << "x" << h;
  }
  const cv::Mat ok(20, 20, CV_8UC1, cv::Scalar(255));
  EXPECT_TRUE(detector.detect(ok).empty());  // the smallest accepted size runs
}

}  // namespace
}  // namespace poise::camera
