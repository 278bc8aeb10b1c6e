// AprilTag detection with libapriltag (C handles owned by RAII wrappers; no apriltag header leaks).
//
// Corner order is libapriltag's: counter-clockwise as seen in the image (x right, y down), starting
// at the tag's bottom-left corner (tag upright): bottom-left, bottom-right, top-right, top-left.
// Corner pixel coordinates follow OpenCV's convention (origin at the centre of the top-left pixel):
// libapriltag's own values are these + 0.5 px (it puts pixel centres at half-integers).
#pragma once

#include <opencv2/core.hpp>

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace poise::camera {

/// libapriltag detector settings. Defaults: the camera pipeline's (speed/accuracy balance).
struct DetectorParams {
  std::string family = "tag36h11";  ///< tag family name (see tag_family_names())
  /// Quad detection on an image decimated by this factor (1 = full resolution, best recall and
  /// range; 2 = about 3x faster, corners still refined on the full image when refine_edges).
  double decimate = 2.0;
  double blur_sigma = 0.0;       ///< Gaussian blur sigma before quad detection, px (0 = none)
  int threads = 1;               ///< libapriltag worker threads (>= 1)
  bool refine_edges = true;      ///< snap quad edges to strong gradients (recommended)
  double decode_sharpening = 0.25;  ///< sharpening of the decoded samples (libapriltag default)
  int max_hamming = 2;           ///< bit errors corrected (0-3; each extra bit costs memory/time)
  double min_decision_margin = 0.0;  ///< detections below this margin are dropped (0 = keep all)
};

/// Throws ConfigError when a field is out of range.
void validate_detector_params(const DetectorParams& params);

/// Four zero corners (Eigen vectors are not zero-initialised by default).
inline std::array<Eigen::Vector2d, 4> zero_corners() {
  return {Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero(),
          Eigen::Vector2d::Zero()};
}

/// One detected tag.
struct TagDetection {
  int id = -1;
  int hamming = 0;                ///< bits corrected
  double decision_margin = 0.0;   ///< libapriltag decision margin (higher = more confident)
  std::array<Eigen::Vector2d, 4> corners_px = zero_corners();  ///< distorted image corners, library order, px
  Eigen::Vector2d center_px{0, 0};            ///< tag centre in the image, px
};

/// Bit layout and codes of a family, copied out of libapriltag's family struct.
struct TagFamilyLayout {
  std::string name;
  std::vector<uint64_t> codes;
  std::vector<uint32_t> bit_x;  ///< per bit (MSB first), cell column relative to the border start
  std::vector<uint32_t> bit_y;  ///< per bit (MSB first), cell row relative to the border start
  uint32_t nbits = 0;
  int width_at_border = 0;  ///< cells across the tag's detected square (= the tag size)
  int total_width = 0;      ///< cells across the whole printed pattern
  bool reversed_border = false;

  /// The tag's pattern, total_width x total_width cells, 255 = white, 0 = black, row 0 on top.
  [[nodiscard]] cv::Mat pattern(int id) const;
};

/// Names libapriltag provides ("tag36h11", "tag25h9", "tag16h5", "tagStandard41h12", ...).
std::vector<std::string> tag_family_names();

/// The layout of a family; throws ConfigError for an unknown family name.
TagFamilyLayout tag_family_layout(const std::string& family);

/// libapriltag's own rendering of a tag (apriltag_to_image), for cross-checks.
cv::Mat apriltag_library_pattern(const std::string& family, int id);

/// A libapriltag detector for one family. Not copyable; one detect() at a time.
class TagDetector {
 public:
  explicit TagDetector(const DetectorParams& params);  ///< throws ConfigError
  ~TagDetector();
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;
  TagDetector(TagDetector&&) noexcept;
  TagDetector& operator=(TagDetector&&) noexcept;

  /// Detects tags in an 8-bit single-channel image (no copy is made). Sorted by id. Throws
  /// std::invalid_argument for an image with a side below min_image_side_px() (libapriltag
  /// crashes on images 2 px high); callers check first and count such frames.
  std::vector<TagDetection> detect(const cv::Mat& gray);

  /// Smallest width and height detect() accepts: after decimation one tag of the family (its
  /// total width in cells, at least 8) must still fit at one pixel per cell.
  [[nodiscard]] int min_image_side_px() const;

  [[nodiscard]] const DetectorParams& params() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace poise::camera
