// Image files from outside are hostile: their size is checked from the header before anything is
// decoded (a 66 KB JPEG can declare 30000x30000 px), and images too small for the detector are
// refused before libapriltag sees them.
#pragma once

#include <opencv2/core.hpp>

#include <cstdint>
#include <string>

namespace poise::camera {

/// Limits on an image handed to the detector. The maximum is configurable (`--max-image-pixels`,
/// `capture.max_image_pixels`); the minimum comes from the detector (TagDetector::min_image_side_px).
struct ImageLimits {
  int min_side_px = 8;                 ///< width and height at least this
  int max_side_px = 32768;             ///< width and height at most this
  int64_t max_pixels = 40'000'000;     ///< width * height at most this (8K UHD is 33 MP)
};

/// Dimensions read from a file's header without decoding it.
struct ImageHeader {
  std::string format;  ///< "png", "jpeg", "bmp", "pnm", "tiff", "webp"; empty: not recognised
  int64_t width = 0;
  int64_t height = 0;
};

/// Reads the header of PNG, JPEG, BMP, PNM (P1-P6), TIFF and WebP files. `format` empty when the
/// file is none of them or its header is cut or inconsistent.
ImageHeader read_image_header(const std::string& path);

/// "" when width x height is within `limits`, else why not ("2x1 px is below the 10 px minimum").
std::string check_image_size(int64_t width, int64_t height, const ImageLimits& limits);

/// Reads `path` as an 8-bit grey image after checking its header against `limits`. Returns an
/// empty Mat and sets `error` (naming the file) when it is missing, unreadable, of a format whose
/// size cannot be checked first, or outside the limits.
cv::Mat read_gray_image(const std::string& path, const ImageLimits& limits, std::string& error);

}  // namespace poise::camera
