#include "poise/camera/image_file.h"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <vector>

namespace poise::camera {
namespace {

/// Random access to the first bytes of a file (headers live there; JPEG may need to skip EXIF).
class Bytes {
 public:
  explicit Bytes(const std::string& path) : in_(path, std::ios::binary) {}
  [[nodiscard]] bool ok() const { return static_cast<bool>(in_); }
  /// Reads n bytes at offset into out; false when the file is shorter.
  bool at(uint64_t offset, std::size_t n, std::vector<unsigned char>& out) {
    out.assign(n, 0);
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(offset));
    in_.read(reinterpret_cast<char*>(out.data()), static_cast<std::streamsize>(n));
    return static_cast<std::size_t>(in_.gcount()) == n;
  }

 private:
  std::ifstream in_;
};

uint32_t be(const unsigned char* p, int n) {
  uint32_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | p[i];
  return v;
}
uint32_t le(const unsigned char* p, int n) {
  uint32_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

ImageHeader make(const char* format, int64_t w, int64_t h) { return ImageHeader{format, w, h}; }

ImageHeader jpeg(Bytes& f) {
  std::vector<unsigned char> b;
  uint64_t pos = 2;
  for (int segments = 0; segments < 1000; ++segments) {
    if (!f.at(pos, 4, b) || b[0] != 0xFF) return {};
    const unsigned m = b[1];
    if (m == 0xFF) {  // fill byte
      ++pos;
      continue;
    }
    if (m == 0xD8 || m == 0x01 || (m >= 0xD0 && m <= 0xD7)) {  // no length
      pos += 2;
      continue;
    }
    const uint32_t len = be(&b[2], 2);
    if (len < 2) return {};
    if (m >= 0xC0 && m <= 0xCF && m != 0xC4 && m != 0xC8 && m != 0xCC) {  // start of frame
      if (!f.at(pos + 4, 5, b)) return {};
      return make("jpeg", be(&b[3], 2), be(&b[1], 2));
    }
    if (m == 0xD9 || m == 0xDA) return {};  // end of image / scan before any frame header
    pos += 2 + len;
  }
  return {};
}

ImageHeader pnm(Bytes& f) {
  std::vector<unsigned char> b;
  const std::size_t n = 4096;
  f.at(0, n, b);  // a short file leaves zeros: the parse below stops at them
  std::size_t i = 2;
  int64_t dims[2] = {0, 0};
  for (int k = 0; k < 2; ++k) {
    for (;;) {  // whitespace and comments
      while (i < n && std::isspace(b[i])) ++i;
      if (i < n && b[i] == '#') {
        while (i < n && b[i] != '\n') ++i;
        continue;
      }
      break;
    }
    if (i >= n || !std::isdigit(b[i])) return {};
    while (i < n && std::isdigit(b[i]) && dims[k] < (int64_t{1} << 40)) dims[k] = dims[k] * 10 + (b[i++] - '0');
  }
  return make("pnm", dims[0], dims[1]);
}

ImageHeader tiff(Bytes& f, bool little) {
  std::vector<unsigned char> b;
  auto u = [little](const unsigned char* p, int n) { return little ? le(p, n) : be(p, n); };
  if (!f.at(4, 4, b)) return {};
  const uint64_t ifd = u(b.data(), 4);
  if (!f.at(ifd, 2, b)) return {};
  const uint32_t entries = u(b.data(), 2);
  int64_t w = -1, h = -1;
  for (uint32_t e = 0; e < entries && e < 4096; ++e) {
    if (!f.at(ifd + 2 + 12ULL * e, 12, b)) return {};
    const uint32_t tag = u(&b[0], 2), type = u(&b[2], 2);
    const int64_t value = type == 3 ? u(&b[8], 2) : type == 4 ? u(&b[8], 4) : -1;
    if (tag == 256) w = value;
    if (tag == 257) h = value;
  }
  return w < 0 || h < 0 ? ImageHeader{} : make("tiff", w, h);
}

ImageHeader webp(Bytes& f) {
  std::vector<unsigned char> b;
  if (!f.at(12, 18, b)) return {};
  if (b[0] == 'V' && b[1] == 'P' && b[2] == '8' && b[3] == ' ') {  // lossy: frame header at 20
    return make("webp", le(&b[14], 2) & 0x3FFF, le(&b[16], 2) & 0x3FFF);
  }
  if (b[0] == 'V' && b[1] == 'P' && b[2] == '8' && b[3] == 'L') {  // lossless: 14-bit sizes - 1
    const uint32_t v = le(&b[9], 4);
    return make("webp", (v & 0x3FFF) + 1, ((v >> 14) & 0x3FFF) + 1);
  }
  if (b[0] == 'V' && b[1] == 'P' && b[2] == '8' && b[3] == 'X') {  // extended: 24-bit sizes - 1
    return make("webp", le(&b[12], 3) + 1, le(&b[15], 3) + 1);
  }
  return {};
}

}  // namespace

ImageHeader read_image_header(const std::string& path) {
  Bytes f(path);
  std::vector<unsigned char> b;
  if (!f.ok() || !f.at(0, 12, b)) {
    if (!f.ok() || !f.at(0, 2, b)) return {};
    b.resize(12, 0);
  }
  if (be(b.data(), 4) == 0x89504E47u) {  // PNG: IHDR first
    std::vector<unsigned char> ihdr;
    if (!f.at(12, 12, ihdr) || std::string(ihdr.begin(), ihdr.begin() + 4) != "IHDR") return {};
    return make("png", be(&ihdr[4], 4), be(&ihdr[8], 4));
  }
  if (b[0] == 0xFF && b[1] == 0xD8) return jpeg(f);
  if (b[0] == 'B' && b[1] == 'M') {
    std::vector<unsigned char> dib;
    if (!f.at(14, 12, dib)) return {};
    if (le(dib.data(), 4) == 12) return make("bmp", le(&dib[4], 2), le(&dib[6], 2));
    const auto h = static_cast<int32_t>(le(&dib[8], 4));  // negative: top-down rows
    return make("bmp", static_cast<int32_t>(le(&dib[4], 4)), h < 0 ? -static_cast<int64_t>(h) : h);
  }
  if (b[0] == 'P' && b[1] >= '1' && b[1] <= '6') return pnm(f);
  if (b[0] == 'I' && b[1] == 'I' && b[2] == 42 && b[3] == 0) return tiff(f, true);
  if (b[0] == 'M' && b[1] == 'M' && b[2] == 0 && b[3] == 42) return tiff(f, false);
  if (std::string(b.begin(), b.begin() + 4) == "RIFF" && std::string(b.begin() + 8, b.begin() + 12) == "WEBP") {
    return webp(f);
  }
  return {};
}

std::string check_image_size(int64_t width, int64_t height, const ImageLimits& limits) {
  const std::string dims = std::to_string(width) + "x" + std::to_string(height) + " px";
  if (width < limits.min_side_px || height < limits.min_side_px) {
    return dims + " is below the " + std::to_string(limits.min_side_px) + " px minimum side (too small for a tag)";
  }
  if (width > limits.max_side_px || height > limits.max_side_px) {
    return dims + " exceeds the " + std::to_string(limits.max_side_px) + " px maximum side";
  }
  if (width * height > limits.max_pixels) {
    return dims + " exceeds the maximum of " + std::to_string(limits.max_pixels) +
           " pixels (raise it with --max-image-pixels / capture.max_image_pixels)";
  }
  return {};
}

cv::Mat read_gray_image(const std::string& path, const ImageLimits& limits, std::string& error) {
  error.clear();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    error = "cannot read image '" + path + "' (missing or not a regular file)";
    return {};
  }
  const ImageHeader h = read_image_header(path);
  if (h.format.empty()) {
    error = "cannot read image '" + path +
            "' (not a PNG, JPEG, BMP, PNM, TIFF or WebP image, or its header is damaged: its size cannot be "
            "checked before decoding)";
    return {};
  }
  if (const std::string why = check_image_size(h.width, h.height, limits); !why.empty()) {
    error = "image '" + path + "' refused: " + h.format + " " + why;
    return {};
  }
  cv::Mat gray;
  try {
    gray = cv::imread(path, cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception&) {
    gray.release();
  }
  if (gray.empty()) {
    error = "cannot read image '" + path + "' (damaged or not decodable)";
    return {};
  }
  // the decoder's size is what counts (a header may lie about it)
  if (const std::string why = check_image_size(gray.cols, gray.rows, limits); !why.empty()) {
    error = "image '" + path + "' refused: " + why;
    return {};
  }
  return gray;
}

}  // namespace poise::camera
