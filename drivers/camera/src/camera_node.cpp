#include "poise/camera/camera_node.h"

#include "poise/camera/camera_msgs.h"
#include "poise/nodes/reports.h"

#include <chrono>
#include <cinttypes>
#include <cstdio>

namespace poise::camera {
namespace {

constexpr uint64_t kLogEverySkip = 100;  // after the first, log every Nth unreadable frame

std::string required(const runtime::ComponentSpec& spec, const char* key, const char* what) {
  const auto value = runtime::param<std::string>(spec, key, "");
  if (value.empty()) {
    throw runtime::ConfigError(spec.origin + ": camera needs '" + key + "' (" + what + ")");
  }
  return value;
}

}  // namespace

CameraNodeOptions camera_node_options(const runtime::ComponentSpec& spec) {
  runtime::check_known_params(spec, {"source", "intrinsics_file", "tags_file", "config_file", "diagnostics_period_s", "pace",
                                     "capture_delay_ms"});
  CameraNodeOptions o;
  o.source = required(spec, "source", "/dev/videoN, a video, images or synthetic");
  o.intrinsics_file = required(spec, "intrinsics_file", "OpenCV or ROS camera_info YAML");
  o.tags_file = required(spec, "tags_file", "tag map YAML, see docs/CAMERA.md");
  o.config_file = runtime::param<std::string>(spec, "config_file", "");
  o.diagnostics_period_s = runtime::param<double>(spec, "diagnostics_period_s", o.diagnostics_period_s);
  if (!(o.diagnostics_period_s > 0.0 && o.diagnostics_period_s <= 3600.0)) {
    throw runtime::ConfigError(spec.origin + ": diagnostics_period_s must be in (0, 3600]");
  }
  o.pace = runtime::param<bool>(spec, "pace", o.pace);
  if (spec.params && spec.params["capture_delay_ms"]) {
    o.capture_delay_ms = runtime::param<double>(spec, "capture_delay_ms", 0.0);
    if (!(o.capture_delay_ms >= 0.0 && o.capture_delay_ms < 1000.0)) {
      throw runtime::ConfigError(spec.origin + ": capture_delay_ms must be in [0, 1000) (ms)");
    }
  }
  return o;
}

namespace {

struct Loaded {
  CameraConfig config;
  CameraIntrinsics intrinsics;
  TagMap map;
};

Loaded load_all(const CameraNodeOptions& o) {
  try {
    Loaded l;
    l.config = o.config_file.empty() ? CameraConfig{} : load_camera_config(o.config_file);
    l.intrinsics = load_intrinsics(o.intrinsics_file);
    l.map = load_tag_map(o.tags_file);
    return l;
  } catch (const ConfigError& e) {
    throw runtime::ConfigError(e.what());
  }
}

}  // namespace

CameraNode::CameraNode(const CameraNodeOptions& options, const std::string& instance_name,
                       runtime::HostContext& host)
    : options_(options),
      detections_writer_(host.participant, host.topics.tag_detections),
      pose_writer_(host.participant, host.topics.vision_pose),
      diag_writer_(host.participant, host.topics.diagnostics) {
  Loaded l = load_all(options);
  config_ = l.config;
  if (options.capture_delay_ms >= 0.0) {
    config_.capture_delay_s = options.capture_delay_ms * 1e-3;
  }
  sensor_id_ = dds::checked_sensor_id(
      (instance_name.empty() || instance_name == "camera") ? config_.sensor_id : instance_name, "camera");
  try {
    pipeline_ = std::make_unique<CameraPipeline>(config_, l.intrinsics, l.map);
    SourceOptions so;
    so.delay_ns = static_cast<int64_t>(config_.capture_delay_s * 1e9);
    so.width_px = config_.width_px;
    so.height_px = config_.height_px;
    so.fps = config_.fps;
    so.pace = options.pace;
    so.image_limits.max_pixels = config_.max_image_pixels;
    so.image_limits.min_side_px = pipeline_->detector().min_image_side_px();
    SyntheticScene scene;
    scene.intrinsics = l.intrinsics;
    scene.family = config_.detector.family;
    for (const auto& [id, tag] : l.map.tags) {
      scene.tags.push_back(SceneTag{id, tag.size_m, tag.T_world_tag});
    }
    so.scene = scene;
    source_ = open_source(options.source, so);
  } catch (const ConfigError& e) {
    throw runtime::ConfigError(e.what());
  }
}

CameraNode::~CameraNode() { stop(); }

void CameraNode::start() {
  if (thread_.joinable()) {
    return;
  }
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void CameraNode::stop() {
  stop_.store(true);
  if (thread_.joinable()) {
    thread_.join();
  }
}

std::string CameraNode::status() const {
  std::lock_guard<std::mutex> lock(status_mutex_);
  return status_.empty() ? "camera " + sensor_id_ + ": starting (" + source_->describe() + ")"
                         : status_;
}

std::string CameraNode::error() const {
  std::lock_guard<std::mutex> lock(status_mutex_);
  return error_;
}

void CameraNode::log(const std::string& message) const {
  if (options_.log_to_stderr) {
    std::fprintf(stderr, "camera %s: %s\n", sensor_id_.c_str(), message.c_str());
  }
}

void CameraNode::run() {
  Frame frame;
  std::string err;
  const auto period_ns = static_cast<int64_t>(options_.diagnostics_period_s * 1e9);
  period_start_ns_ = monotonic_now_ns();
  while (!stop_.load()) {
    GrabStatus st = GrabStatus::kEnd;
    try {
      st = source_->grab(frame, err);
    } catch (const std::exception& e) {
      err = e.what();
      st = GrabStatus::kEnd;
    }
    if (st == GrabStatus::kEnd) {
      {
        std::lock_guard<std::mutex> lock(status_mutex_);
        error_ = err;
      }
      log(err.empty() ? "source ended (" + source_->describe() + ")" : "source ended: " + err);
      break;
    }
    if (st == GrabStatus::kSkipped) {
      if (source_skipped_++ % kLogEverySkip == 0) {
        log(err + " (skipped; " + std::to_string(source_skipped_) + " so far)");
      }
      continue;
    }
    FrameResult r;
    try {
      r = pipeline_->process(frame);
    } catch (const ConfigError& e) {
      {
        std::lock_guard<std::mutex> lock(status_mutex_);
        error_ = e.what();
      }
      failed_.store(true);
      log(e.what());
      break;  // a setup mismatch (resolution): every further frame would fail the same way
    }
    frames_.fetch_add(1);
    if (!detections_writer_.write(to_tag_detections_msg(r, sensor_id_, config_.frame_id,
                                                        config_.detector.family, detections_seq_++,
                                                        &truncated_))) {
      ++write_failures_;
    }
    if (r.world.valid) {
      if (!pose_writer_.write(to_vision_pose_msg(r, sensor_id_, pose_seq_++))) {
        ++write_failures_;
      }
      poses_.fetch_add(1);
    }
    const int64_t now = monotonic_now_ns();
    ++period_frames_;
    period_detect_ms_ += r.detect_ms;
    period_total_ms_ += r.total_ms;
    period_latency_ms_ += static_cast<double>(now - r.stamp_ns) * 1e-6;
    if (now - period_start_ns_ >= period_ns) {
      publish_diagnostics(r.stamp_ns);
    }
  }
  finished_.store(true);
}

void CameraNode::publish_diagnostics(int64_t stamp_ns) {
  const int64_t now = monotonic_now_ns();
  const double seconds = static_cast<double>(now - period_start_ns_) * 1e-9;
  const double n = period_frames_ > 0 ? static_cast<double>(period_frames_) : 1.0;
  nodes::DiagnosticsReport report;
  report.stamp_ns = stamp_ns;
  report.seq = diag_seq_++;
  report.component = "camera";
  report.counters = pipeline_->counters();
  report.counters["source_skipped"] = source_skipped_;
  report.counters["dds_write_failures"] = write_failures_;
  report.counters["detections_truncated"] = truncated_;
  report.metrics.push_back({"rate", seconds > 0.0 ? static_cast<double>(period_frames_) / seconds : 0.0, "Hz"});
  report.metrics.push_back({"detect_time", period_detect_ms_ / n, "ms"});
  report.metrics.push_back({"pipeline_time", period_total_ms_ / n, "ms"});
  report.metrics.push_back({"latency", period_latency_ms_ / n, "ms"});
  if (!diag_writer_.write(nodes::to_diagnostics_msg(report, sensor_id_))) {
    ++write_failures_;
  }
  const auto& c = pipeline_->counters();
  auto count = [&c](const char* key) {
    const auto it = c.find(key);
    return it == c.end() ? uint64_t{0} : it->second;
  };
  char line[400];
  std::snprintf(line, sizeof line,
                "camera %s: %.1f fps, %" PRIu64 " frames, %" PRIu64 " with tags, %" PRIu64
                " poses, %" PRIu64 " ambiguous, pipeline %.1f ms (detect %.1f), latency %.1f ms",
                sensor_id_.c_str(), seconds > 0.0 ? static_cast<double>(period_frames_) / seconds : 0.0,
                count("frames"), count("frames_with_tags"), count("world_pose_ok"),
                count("world_rejected_ambiguous"), period_total_ms_ / n, period_detect_ms_ / n,
                period_latency_ms_ / n);
  {
    std::lock_guard<std::mutex> lock(status_mutex_);
    status_ = line;
  }
  period_start_ns_ = now;
  period_frames_ = 0;
  period_detect_ms_ = 0.0;
  period_total_ms_ = 0.0;
  period_latency_ms_ = 0.0;
}

}  // namespace poise::camera

namespace poise::runtime {
void register_camera_component(ComponentRegistry& registry) {
  ComponentType t;
  t.name = "camera";
  t.description =
      "AprilTag camera: source -> tag_detections + vision_pose (camera/body pose in world)";
  t.standalone_command = false;  // `poise camera` is its dedicated command
  t.create = [](const ComponentSpec& spec, HostContext& host) -> std::unique_ptr<Component> {
    return std::make_unique<camera::CameraNode>(camera::camera_node_options(spec), spec.name, host);
  };
  registry.add(std::move(t));
}
}  // namespace poise::runtime
