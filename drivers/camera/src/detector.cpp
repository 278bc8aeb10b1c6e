#include "poise/camera/detector.h"

#include "poise/camera/intrinsics.h"  // ConfigError

#include <apriltag.h>
#include <tag16h5.h>
#include <tag25h9.h>
#include <tag36h10.h>
#include <tag36h11.h>
#include <tagCircle21h7.h>
#include <tagCircle49h12.h>
#include <tagCustom48h12.h>
#include <tagStandard41h12.h>
#include <tagStandard52h13.h>

#include <algorithm>
#include <cmath>

namespace poise::camera {
namespace {

// libapriltag places a pixel's centre at (i + 0.5, j + 0.5) (AprilRobotics/apriltag issues 121,
// 334); OpenCV and our messages at (i, j). Measured on rendered tags (random poses, blur 0 and 1 px,
// decimate 1 and 2): mean library-minus-true offset 0.49-0.50 px on both axes. Subtracting it leaves a
// corner RMS error below 0.1 px (tests/camera: DetectorTest.CornersMatchRenderedTruth).
constexpr double kLibraryPixelOffset = 0.5;

struct FamilyEntry {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};

const FamilyEntry kFamilies[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tag36h10", tag36h10_create, tag36h10_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
};

const FamilyEntry& find_family(const std::string& name) {
  for (const auto& entry : kFamilies) {
    if (name == entry.name) {
      return entry;
    }
  }
  std::string known;
  for (const auto& entry : kFamilies) {
    known += (known.empty() ? "" : ", ") + std::string(entry.name);
  }
  throw ConfigError("unknown tag family '" + name + "' (known: " + known + ")");
}

/// Owns an apriltag_family_t.
class FamilyHandle {
 public:
  explicit FamilyHandle(const std::string& name) : entry_(&find_family(name)) {
    family_ = entry_->create();
    if (family_ == nullptr) {
      throw ConfigError("libapriltag could not create family '" + name + "'");
    }
  }
  ~FamilyHandle() {
    if (family_ != nullptr) {
      entry_->destroy(family_);
    }
  }
  FamilyHandle(const FamilyHandle&) = delete;
  FamilyHandle& operator=(const FamilyHandle&) = delete;
  [[nodiscard]] apriltag_family_t* get() const { return family_; }

 private:
  const FamilyEntry* entry_;
  apriltag_family_t* family_ = nullptr;
};

struct DetectorDeleter {
  void operator()(apriltag_detector_t* td) const { apriltag_detector_destroy(td); }
};
struct DetectionsDeleter {
  void operator()(zarray_t* detections) const { apriltag_detections_destroy(detections); }
};
struct ImageDeleter {
  void operator()(image_u8_t* im) const { image_u8_destroy(im); }
};

}  // namespace

void validate_detector_params(const DetectorParams& p) {
  (void)find_family(p.family);
  if (!(p.decimate >= 1.0) || p.decimate > 8.0) {
    throw ConfigError("detector.decimate must be in [1, 8], got " + std::to_string(p.decimate));
  }
  if (!(p.blur_sigma >= 0.0) || p.blur_sigma > 10.0) {
    throw ConfigError("detector.blur_sigma must be in [0, 10] px, got " +
                      std::to_string(p.blur_sigma));
  }
  if (p.threads < 1 || p.threads > 64) {
    throw ConfigError("detector.threads must be in [1, 64], got " + std::to_string(p.threads));
  }
  if (!(p.decode_sharpening >= 0.0) || p.decode_sharpening > 10.0) {
    throw ConfigError("detector.decode_sharpening must be in [0, 10]");
  }
  if (p.max_hamming < 0 || p.max_hamming > 3) {
    throw ConfigError("detector.max_hamming must be in [0, 3], got " +
                      std::to_string(p.max_hamming));
  }
  if (!(p.min_decision_margin >= 0.0)) {
    throw ConfigError("detector.min_decision_margin must be >= 0");
  }
}

cv::Mat TagFamilyLayout::pattern(int id) const {
  if (id < 0 || static_cast<std::size_t>(id) >= codes.size()) {
    throw ConfigError("tag id " + std::to_string(id) + " is not in family " + name + " (0-" +
                      std::to_string(codes.size() - 1) + ")");
  }
  // Everything black, then the white ring just outside (or, for reversed-border families, just
  // inside) the detected square, then the white data bits (code bit i, MSB first, at
  // (bit_x[i], bit_y[i]) counted from the square's top-left cell).
  cv::Mat out(total_width, total_width, CV_8UC1, cv::Scalar(0));
  const int ring = width_at_border + (reversed_border ? 0 : 2);
  const int ring_start = (total_width - ring) / 2;
  for (int i = 0; i < ring; ++i) {
    for (int j : {0, ring - 1}) {
      out.at<uint8_t>(ring_start + j, ring_start + i) = 255;
      out.at<uint8_t>(ring_start + i, ring_start + j) = 255;
    }
  }
  const int border_start = (total_width - width_at_border) / 2;
  const uint64_t code = codes[static_cast<std::size_t>(id)];
  for (uint32_t i = 0; i < nbits; ++i) {
    if ((code >> (nbits - 1 - i)) & 1U) {
      out.at<uint8_t>(static_cast<int>(bit_y[i]) + border_start,
                      static_cast<int>(bit_x[i]) + border_start) = 255;
    }
  }
  return out;
}

std::vector<std::string> tag_family_names() {
  std::vector<std::string> names;
  for (const auto& entry : kFamilies) {
    names.emplace_back(entry.name);
  }
  return names;
}

TagFamilyLayout tag_family_layout(const std::string& family) {
  FamilyHandle handle(family);
  const apriltag_family_t* f = handle.get();
  TagFamilyLayout out;
  out.name = family;
  out.codes.assign(f->codes, f->codes + f->ncodes);
  out.bit_x.assign(f->bit_x, f->bit_x + f->nbits);
  out.bit_y.assign(f->bit_y, f->bit_y + f->nbits);
  out.nbits = f->nbits;
  out.width_at_border = f->width_at_border;
  out.total_width = f->total_width;
  out.reversed_border = f->reversed_border;
  return out;
}

cv::Mat apriltag_library_pattern(const std::string& family, int id) {
  FamilyHandle handle(family);
  if (id < 0 || static_cast<uint32_t>(id) >= handle.get()->ncodes) {
    throw ConfigError("tag id out of range for " + family);
  }
  std::unique_ptr<image_u8_t, ImageDeleter> im(apriltag_to_image(handle.get(), id));
  cv::Mat view(im->height, im->width, CV_8UC1, im->buf, static_cast<std::size_t>(im->stride));
  return view.clone();
}

struct TagDetector::Impl {
  DetectorParams params;
  FamilyHandle family;
  std::unique_ptr<apriltag_detector_t, DetectorDeleter> detector;

  explicit Impl(const DetectorParams& p) : params(p), family(p.family) {
    detector.reset(apriltag_detector_create());
    if (!detector) {
      throw ConfigError("libapriltag could not create a detector");
    }
    apriltag_detector_add_family_bits(detector.get(), family.get(), p.max_hamming);
    detector->quad_decimate = static_cast<float>(p.decimate);
    detector->quad_sigma = static_cast<float>(p.blur_sigma);
    detector->nthreads = p.threads;
    detector->refine_edges = p.refine_edges;
    detector->decode_sharpening = p.decode_sharpening;
  }
  ~Impl() {
    // The detector references the family: detach it before the family is destroyed.
    if (detector) {
      apriltag_detector_clear_families(detector.get());
    }
    detector.reset();
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
};

TagDetector::TagDetector(const DetectorParams& params) {
  validate_detector_params(params);
  impl_ = std::make_unique<Impl>(params);
}

TagDetector::~TagDetector() = default;
TagDetector::TagDetector(TagDetector&&) noexcept = default;
TagDetector& TagDetector::operator=(TagDetector&&) noexcept = default;

const DetectorParams& TagDetector::params() const { return impl_->params; }

int TagDetector::min_image_side_px() const {
  const int cells = std::max(impl_->family.get()->total_width, 8);
  return static_cast<int>(std::ceil(cells * std::max(1.0, impl_->params.decimate)));
}

std::vector<TagDetection> TagDetector::detect(const cv::Mat& gray) {
  if (gray.empty() || gray.type() != CV_8UC1) {
    throw std::invalid_argument("TagDetector::detect needs a non-empty 8-bit grey image");
  }
  if (gray.cols < min_image_side_px() || gray.rows < min_image_side_px()) {
    throw std::invalid_argument("TagDetector::detect: a " + std::to_string(gray.cols) + "x" +
                                std::to_string(gray.rows) + " image is below the " +
                                std::to_string(min_image_side_px()) + " px minimum side");
  }
  image_u8_t im{gray.cols, gray.rows, static_cast<int32_t>(gray.step[0]),
                const_cast<uint8_t*>(gray.ptr<uint8_t>(0))};  // libapriltag only reads it
  std::unique_ptr<zarray_t, DetectionsDeleter> found(
      apriltag_detector_detect(impl_->detector.get(), &im));
  std::vector<TagDetection> out;
  if (!found) {
    return out;
  }
  const int n = zarray_size(found.get());
  out.reserve(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    apriltag_detection_t* det = nullptr;
    zarray_get(found.get(), i, &det);
    if (static_cast<double>(det->decision_margin) < impl_->params.min_decision_margin) {
      continue;
    }
    TagDetection d;
    d.id = det->id;
    d.hamming = det->hamming;
    d.decision_margin = static_cast<double>(det->decision_margin);
    for (int c = 0; c < 4; ++c) {
      d.corners_px[static_cast<std::size_t>(c)] = {det->p[c][0] - kLibraryPixelOffset,
                                                    det->p[c][1] - kLibraryPixelOffset};
    }
    d.center_px = {det->c[0] - kLibraryPixelOffset, det->c[1] - kLibraryPixelOffset};
    out.push_back(d);
  }
  std::sort(out.begin(), out.end(),
            [](const TagDetection& a, const TagDetection& b) { return a.id < b.id; });
  return out;
}

}  // namespace poise::camera
