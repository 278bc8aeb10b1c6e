#include "poise/camera/capture.h"
#include "poise/camera/image_file.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <glob.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <map>
#include <sstream>
#include <thread>

namespace poise::camera {
namespace {

namespace fs = std::filesystem;

constexpr int kMaxConsecutiveDeviceFailures = 30;  // then the device is considered gone

std::string lower_extension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

bool is_image_file(const std::string& path) {
  static const char* const kExt[] = {".png", ".jpg", ".jpeg", ".pgm", ".ppm", ".pnm",
                                     ".bmp", ".tif", ".tiff", ".webp"};
  const auto ext = lower_extension(path);
  return std::any_of(std::begin(kExt), std::end(kExt), [&ext](const char* e) { return ext == e; });
}

bool is_video_file(const std::string& path) {
  static const char* const kExt[] = {".mp4", ".avi", ".mkv", ".mov", ".webm", ".m4v", ".mjpeg"};
  const auto ext = lower_extension(path);
  return std::any_of(std::begin(kExt), std::end(kExt), [&ext](const char* e) { return ext == e; });
}

bool starts_with(const std::string& s, const std::string& prefix) {
  return s.rfind(prefix, 0) == 0;
}

int64_t host_stamp(const SourceOptions& o) { return o.clock() - o.delay_ns; }

// ---------------------------------------------------------------------------------------------
class DeviceSource : public FrameSource {
 public:
  DeviceSource(const std::string& device, const SourceOptions& options)
      : device_(device), options_(options) {
    struct stat st {};
    if (::stat(device.c_str(), &st) != 0) {
      throw ConfigError("camera device " + device +
                        " does not exist: list cameras with `v4l2-ctl --list-devices` (or "
                        "`ls /dev/video*`) and pass --source /dev/videoN");
    }
    if (::access(device.c_str(), R_OK | W_OK) != 0) {
      throw ConfigError("no permission to open " + device +
                        ": add your user to the 'video' group (sudo usermod -aG video $USER) "
                        "and log in again");
    }
    cap_.open(device, cv::CAP_V4L2);
    if (!cap_.isOpened()) {
      throw ConfigError("cannot open camera " + device +
                        " with V4L2: is it a capture device (not a metadata node) and not in use "
                        "by another program?");
    }
    if (options.width_px > 0 && options.height_px > 0) {
      cap_.set(cv::CAP_PROP_FRAME_WIDTH, options.width_px);
      cap_.set(cv::CAP_PROP_FRAME_HEIGHT, options.height_px);
    }
    if (options.fps > 0.0) {
      cap_.set(cv::CAP_PROP_FPS, options.fps);
    }
  }

  GrabStatus grab(Frame& frame, std::string& error) override {
    if (!cap_.read(frame.image) || frame.image.empty()) {
      if (++failures_ >= kMaxConsecutiveDeviceFailures) {
        error = "camera " + device_ + " stopped delivering frames (unplugged?)";
        return GrabStatus::kEnd;
      }
      error = "camera " + device_ + ": frame grab failed";
      return GrabStatus::kSkipped;
    }
    failures_ = 0;
    const int64_t host = options_.clock();
    // OpenCV's V4L2 backend reports the buffer's driver timestamp (CLOCK_MONOTONIC on current
    // kernels) as CAP_PROP_POS_MSEC.
    const double driver_ms = cap_.get(cv::CAP_PROP_POS_MSEC);
    const auto driver_ns = static_cast<int64_t>(std::llround(driver_ms * 1e6));
    if (driver_ms > 0.0 && std::llabs(host - driver_ns) < options_.max_driver_skew_ns) {
      frame.stamp_ns = driver_ns;
      frame.stamp_from_driver = true;
    } else {
      frame.stamp_ns = host - options_.delay_ns;
      frame.stamp_from_driver = false;
    }
    frame.index = index_++;
    frame.name.clear();
    return GrabStatus::kFrame;
  }

  [[nodiscard]] std::string describe() const override {
    std::ostringstream o;
    o << "v4l2 " << device_ << " " << static_cast<int>(cap_.get(cv::CAP_PROP_FRAME_WIDTH)) << "x"
      << static_cast<int>(cap_.get(cv::CAP_PROP_FRAME_HEIGHT));
    return o.str();
  }

 private:
  std::string device_;
  SourceOptions options_;
  cv::VideoCapture cap_;
  uint64_t index_ = 0;
  int failures_ = 0;
};

// ---------------------------------------------------------------------------------------------
class VideoFileSource : public FrameSource {
 public:
  VideoFileSource(const std::string& path, const SourceOptions& options)
      : path_(path), options_(options) {
    if (!fs::is_regular_file(path)) {
      throw ConfigError("video file '" + path + "' does not exist");
    }
    cap_.open(path, cv::CAP_ANY);
    if (!cap_.isOpened()) {
      throw ConfigError("cannot decode video file '" + path +
                        "' (unsupported container/codec for this OpenCV build?)");
    }
  }

  GrabStatus grab(Frame& frame, std::string& /*error*/) override {
    if (!cap_.read(frame.image) || frame.image.empty()) {
      return GrabStatus::kEnd;
    }
    // Stamps: host time of the first frame, then the file's own media time.
    const double pos_ms = cap_.get(cv::CAP_PROP_POS_MSEC);
    if (index_ == 0) {
      first_stamp_ns_ = host_stamp(options_);
      first_pos_ms_ = pos_ms;
    }
    frame.stamp_ns = first_stamp_ns_ + static_cast<int64_t>(std::llround((pos_ms - first_pos_ms_) * 1e6));
    frame.stamp_from_driver = false;
    frame.index = index_++;
    frame.name = path_;
    return GrabStatus::kFrame;
  }

  [[nodiscard]] std::string describe() const override { return "video file " + path_; }

 private:
  std::string path_;
  SourceOptions options_;
  cv::VideoCapture cap_;
  uint64_t index_ = 0;
  int64_t first_stamp_ns_ = 0;
  double first_pos_ms_ = 0.0;
};

// ---------------------------------------------------------------------------------------------
class ImageListSource : public FrameSource {
 public:
  ImageListSource(std::vector<std::string> files, const std::string& spec,
                  const SourceOptions& options)
      : files_(std::move(files)), spec_(spec), options_(options) {}

  GrabStatus grab(Frame& frame, std::string& error) override {
    if (next_ >= files_.size()) {
      return GrabStatus::kEnd;
    }
    const std::string& path = files_[next_++];
    frame.name = path;
    frame.index = index_++;
    frame.truth_T_world_camera.reset();
    frame.image = read_gray_image(path, options_.image_limits, error);  // size checked before decoding
    if (frame.image.empty()) {
      return GrabStatus::kSkipped;
    }
    frame.stamp_ns = host_stamp(options_);
    frame.stamp_from_driver = false;
    return GrabStatus::kFrame;
  }

  [[nodiscard]] std::string describe() const override {
    return "images " + spec_ + " (" + std::to_string(files_.size()) + " files)";
  }

 private:
  std::vector<std::string> files_;
  std::string spec_;
  SourceOptions options_;
  std::size_t next_ = 0;
  uint64_t index_ = 0;
};

// ---------------------------------------------------------------------------------------------
struct SyntheticSettings {
  uint64_t frames = 300;
  double fps = 30.0;
  uint64_t seed = 1;
  double noise = 2.0;
  double blur = 0.6;
};

SyntheticSettings parse_synthetic(const std::string& spec) {
  SyntheticSettings s;
  const auto colon = spec.find(':');
  if (colon == std::string::npos) {
    return s;
  }
  std::stringstream items(spec.substr(colon + 1));
  std::string item;
  while (std::getline(items, item, ',')) {
    const auto eq = item.find('=');
    if (eq == std::string::npos) {
      throw ConfigError("synthetic source option '" + item + "' is not key=value");
    }
    const std::string key = item.substr(0, eq);
    const std::string value = item.substr(eq + 1);
    try {
      if (key == "frames") {
        s.frames = std::stoull(value);
      } else if (key == "fps") {
        s.fps = std::stod(value);
      } else if (key == "seed") {
        s.seed = std::stoull(value);
      } else if (key == "noise") {
        s.noise = std::stod(value);
      } else if (key == "blur") {
        s.blur = std::stod(value);
      } else {
        throw ConfigError("unknown synthetic source option '" + key +
                          "' (frames, fps, seed, noise, blur)");
      }
    } catch (const std::logic_error&) {
      throw ConfigError("synthetic source option '" + item + "' has a bad value");
    }
  }
  if (!(s.fps > 0.0) || !(s.noise >= 0.0) || !(s.blur >= 0.0)) {
    throw ConfigError("synthetic source: fps must be > 0, noise and blur >= 0");
  }
  return s;
}

/// A slow orbit in front of the tags: 1.2-2 m from their centroid along their mean normal.
std::function<Eigen::Isometry3d(uint64_t)> default_orbit(const std::vector<SceneTag>& tags,
                                                         double fps) {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (const auto& t : tags) {
    centroid += t.T_world_tag.translation();
    normal += t.T_world_tag.linear().col(2);
  }
  centroid /= static_cast<double>(tags.size());
  normal = normal.norm() > 1e-9 ? normal.normalized() : Eigen::Vector3d::UnitZ();
  Eigen::Vector3d up = tags.front().T_world_tag.linear().col(1);
  const Eigen::Vector3d side = up.cross(normal).normalized();
  up = normal.cross(side);
  return [=](uint64_t i) {
    const double t = static_cast<double>(i) / fps;
    const double a = 0.4 * t;
    const Eigen::Vector3d eye = centroid + normal * (1.6 + 0.4 * std::sin(0.7 * a)) +
                                side * (0.5 * std::sin(a)) + up * (0.25 * std::cos(a));
    return look_at(eye, centroid, up);
  };
}

class SyntheticSource : public FrameSource {
 public:
  SyntheticSource(const std::string& spec, const SourceOptions& options)
      : settings_(parse_synthetic(spec)),
        options_(options),
        scene_(*options.scene),
        renderer_(scene_.intrinsics, scene_.family, 2) {
    if (scene_.tags.empty()) {
      throw ConfigError("synthetic source: the tag map has no tags to render");
    }
    if (!scene_.trajectory) {
      scene_.trajectory = default_orbit(scene_.tags, settings_.fps);
    }
    render_options_.noise_sigma = settings_.noise;
    render_options_.blur_sigma_px = settings_.blur;
  }

  GrabStatus grab(Frame& frame, std::string& /*error*/) override {
    if (index_ >= settings_.frames) {
      return GrabStatus::kEnd;
    }
    if (options_.pace) {
      if (index_ == 0) {
        start_ = std::chrono::steady_clock::now();
      }
      std::this_thread::sleep_until(
          start_ + std::chrono::nanoseconds(static_cast<int64_t>(
                       1e9 * static_cast<double>(index_) / settings_.fps)));
    }
    const Eigen::Isometry3d pose = scene_.trajectory(index_);
    render_options_.seed = settings_.seed * 1000003ULL + index_;
    frame.image = renderer_.render(scene_.tags, pose, render_options_);
    frame.truth_T_world_camera = pose;
    frame.stamp_ns = host_stamp(options_);
    frame.stamp_from_driver = false;
    frame.index = index_++;
    frame.name.clear();
    return GrabStatus::kFrame;
  }

  [[nodiscard]] std::string describe() const override {
    std::ostringstream o;
    o << "synthetic " << scene_.intrinsics.width_px << "x" << scene_.intrinsics.height_px << ", "
      << scene_.tags.size() << " tags, " << settings_.frames << " frames";
    return o.str();
  }

 private:
  SyntheticSettings settings_;
  SourceOptions options_;
  SyntheticScene scene_;
  SceneRenderer renderer_;
  RenderOptions render_options_;
  uint64_t index_ = 0;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace

int64_t monotonic_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000LL + ts.tv_nsec;
}

std::vector<std::string> expand_image_spec(const std::string& spec) {
  std::vector<std::string> files;
  if (spec.find_first_of("*?[") != std::string::npos) {
    glob_t g{};
    if (::glob(spec.c_str(), 0, nullptr, &g) == 0) {
      for (std::size_t i = 0; i < g.gl_pathc; ++i) {
        files.emplace_back(g.gl_pathv[i]);
      }
    }
    globfree(&g);
  } else if (fs::is_directory(spec)) {
    for (const auto& entry : fs::directory_iterator(spec)) {
      if (entry.is_regular_file() && is_image_file(entry.path().string())) {
        files.push_back(entry.path().string());
      }
    }
  } else {
    files.push_back(spec);
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::unique_ptr<FrameSource> open_source(const std::string& spec, const SourceOptions& options) {
  if (spec.empty()) {
    throw ConfigError("empty --source: give /dev/videoN, a video file, images or 'synthetic'");
  }
  if (starts_with(spec, "synthetic")) {
    if (!options.scene) {
      throw ConfigError("the synthetic source needs intrinsics and a tag map to render");
    }
    return std::make_unique<SyntheticSource>(spec, options);
  }
  if (starts_with(spec, "v4l2:")) {
    std::string dev = spec.substr(5);
    if (!dev.empty() && std::all_of(dev.begin(), dev.end(),
                                    [](unsigned char c) { return std::isdigit(c) != 0; })) {
      dev = "/dev/video" + dev;
    }
    return std::make_unique<DeviceSource>(dev, options);
  }
  if (starts_with(spec, "/dev/")) {
    return std::make_unique<DeviceSource>(spec, options);
  }
  if (starts_with(spec, "file:")) {
    return std::make_unique<VideoFileSource>(spec.substr(5), options);
  }
  if (spec.find_first_of("*?[") == std::string::npos && !fs::is_directory(spec) &&
      is_video_file(spec)) {
    return std::make_unique<VideoFileSource>(spec, options);
  }
  if (spec.find_first_of("*?[") == std::string::npos && !fs::exists(spec)) {
    throw ConfigError("source '" + spec +
                      "' not found: give /dev/videoN, v4l2:N, a video file, an image, a "
                      "directory of images, a quoted glob, or synthetic");
  }
  auto files = expand_image_spec(spec);
  if (files.empty()) {
    throw ConfigError("no images match '" + spec + "'");
  }
  return std::make_unique<ImageListSource>(std::move(files), spec, options);
}

}  // namespace poise::camera
