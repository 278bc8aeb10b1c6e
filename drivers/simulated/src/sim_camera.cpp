#include "poise/simulated/sim_camera.h"

#include "poise/camera/camera_msgs.h"
#include "poise/camera/pipeline.h"
#include "poise/camera/renderer.h"
#include "poise/dds/convert.h"
#include "poise/nodes/imu_estimator_node.h"
#include "poise/simulated/sim_imu.h"

#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <atomic>
#include <cmath>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

namespace poise::simulated {
namespace {

struct SimCameraParams {
  double fps = 10.0;
  int width_px = 640;
  int height_px = 480;
  double focal_px = 460.0;
  double tag_size_m = 0.24;
  double tag_spacing_m = 0.7;
  double floor_z_m = -1.2;
  std::vector<std::pair<double, double>> blackouts;
  double blackout_period_s = 30.0;
  double noise = 2.0;
  uint64_t seed = 1;
  /// The pipeline's prior corner noise (pose.pixel_sigma_px; its default unless told).
  double pixel_sigma_px = camera::WorldPoseParams{}.pixel_sigma_px;
};

SimCameraParams load(const runtime::ComponentSpec& spec) {
  runtime::check_known_params(spec, {"fps", "width_px", "height_px", "focal_px", "tag_size_m",
                                     "tag_spacing_m", "floor_z_m", "blackouts", "blackout_period_s",
                                     "noise", "seed", "pixel_sigma_px"});
  SimCameraParams p;
  p.fps = runtime::param<double>(spec, "fps", p.fps);
  p.width_px = runtime::param<int>(spec, "width_px", p.width_px);
  p.height_px = runtime::param<int>(spec, "height_px", p.height_px);
  p.focal_px = runtime::param<double>(spec, "focal_px", p.focal_px);
  p.tag_size_m = runtime::param<double>(spec, "tag_size_m", p.tag_size_m);
  p.tag_spacing_m = runtime::param<double>(spec, "tag_spacing_m", p.tag_spacing_m);
  p.floor_z_m = runtime::param<double>(spec, "floor_z_m", p.floor_z_m);
  p.blackouts = runtime::param<std::vector<std::pair<double, double>>>(spec, "blackouts", {});
  p.blackout_period_s = runtime::param<double>(spec, "blackout_period_s", p.blackout_period_s);
  p.noise = runtime::param<double>(spec, "noise", p.noise);
  p.seed = runtime::param<uint64_t>(spec, "seed", p.seed);
  p.pixel_sigma_px = runtime::param<double>(spec, "pixel_sigma_px", p.pixel_sigma_px);
  if (!(p.fps > 0.0 && p.fps <= 120.0) || p.width_px < 64 || p.height_px < 48 || !(p.focal_px > 0.0) ||
      !(p.tag_size_m > 0.0) || !(p.floor_z_m < 0.0)) {
    throw runtime::ConfigError(spec.origin + ": sim_camera parameters out of range (fps (0,120], "
                               "image >= 64x48, focal_px > 0, tag_size_m > 0, floor_z_m < 0)");
  }
  return p;
}

class SimCamera : public runtime::Component {
 public:
  SimCamera(const runtime::ComponentSpec& spec, runtime::HostContext& host)
      : p_(load(spec)),
        sensor_id_(spec.name),
        detections_writer_(host.participant, host.topics.tag_detections, dds::QosKind::kSensor),
        pose_writer_(host.participant, host.topics.vision_pose, dds::QosKind::kEstimate) {
    intrinsics_.width_px = p_.width_px;
    intrinsics_.height_px = p_.height_px;
    intrinsics_.fx_px = intrinsics_.fy_px = p_.focal_px;
    intrinsics_.cx_px = (p_.width_px - 1) / 2.0;
    intrinsics_.cy_px = (p_.height_px - 1) / 2.0;
    camera::TagMap map;
    map.family = "tag36h11";
    int id = 0;
    for (int i = -1; i <= 1; ++i) {
      for (int j = -1; j <= 1; ++j) {
        camera::MappedTag t;
        t.id = id;
        t.size_m = p_.tag_size_m;
        t.T_world_tag.translation() = Eigen::Vector3d(i * p_.tag_spacing_m, j * p_.tag_spacing_m, p_.floor_z_m);
        map.tags[id] = t;
        scene_.push_back({id, p_.tag_size_m, t.T_world_tag});
        ++id;
      }
    }
    T_body_camera_.linear() = Eigen::Matrix3d(Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal());
    camera::CameraConfig config;
    config.sensor_id = sensor_id_;
    config.T_body_camera = T_body_camera_;
    config.world_pose.pixel_sigma_px = p_.pixel_sigma_px;
    // its corners are libapriltag's fitted-line intersections on a clean render: measured to
    // follow the edge-line model (docs/CAMERA.md "Covariance")
    config.world_pose.corner_noise = camera::CornerNoise::kEdgeLines;
    try {
      camera::validate_world_pose_params(config.world_pose);
      pipeline_ = std::make_unique<camera::CameraPipeline>(config, intrinsics_, map);
      renderer_ = std::make_unique<camera::SceneRenderer>(intrinsics_, "tag36h11", 2);
    } catch (const std::exception& e) {
      throw runtime::ConfigError(spec.origin + ": " + e.what());
    }
    truth_reader_ = std::make_unique<dds::Reader<msg::PoseEstimatePubSubType>>(
        host.participant, kTruthPoseTopic, dds::QosKind::kEstimate,
        [this](const msg::PoseEstimate& m, const auto&) {
          Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
          T.linear() = dds::from_msg(m.q_world_body()).normalized().toRotationMatrix();
          T.translation() = dds::from_msg(m.position_m());
          std::lock_guard<std::mutex> lock(mutex_);
          latest_ = T;
          latest_stamp_ns_ = m.header().stamp_ns();
        });
  }

  ~SimCamera() override { SimCamera::stop(); }

  void start() override {
    start_ns_ = nodes::monotonic_ns();
    if (!thread_.joinable()) {
      thread_ = std::thread([this] { run(); });
    }
  }
  void stop() override {
    stop_.store(true);
    if (thread_.joinable()) {
      thread_.join();
    }
  }
  /// Frames rendered or blacked out (the service watchdog's health check).
  [[nodiscard]] std::optional<uint64_t> produced() const override { return frames_.load() + blacked_out_.load(); }
  [[nodiscard]] std::string status() const override {
    std::ostringstream os;
    os << "frames " << frames_.load() << ", vision poses " << poses_.load() << ", blacked out "
       << blacked_out_.load();
    return os.str();
  }

 private:
  [[nodiscard]] bool blacked_out(double t_s) const {
    double local = t_s;
    if (p_.blackout_period_s > 0.0) {
      local = std::fmod(t_s, p_.blackout_period_s);
    }
    for (const auto& [a, b] : p_.blackouts) {
      if (local >= a && local < b) {
        return true;
      }
    }
    return false;
  }

  void run() {
    const auto period_ns = static_cast<int64_t>(1e9 / p_.fps);
    int64_t next = nodes::monotonic_ns();
    uint32_t seq = 0;
    uint64_t index = 0;
    while (!stop_.load()) {
      next += period_ns;
      while (!stop_.load() && nodes::monotonic_ns() < next) {
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
      std::optional<Eigen::Isometry3d> T_world_body;
      int64_t stamp = 0;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        T_world_body = latest_;
        stamp = latest_stamp_ns_;
      }
      if (!T_world_body || stop_.load()) {
        continue;
      }
      if (blacked_out(static_cast<double>(nodes::monotonic_ns() - start_ns_) * 1e-9)) {
        blacked_out_.fetch_add(1);
        continue;
      }
      camera::RenderOptions render;
      render.noise_sigma = p_.noise;
      render.seed = p_.seed + index;
      camera::Frame frame;
      frame.image = renderer_->render(scene_, *T_world_body * T_body_camera_, render);
      frame.stamp_ns = stamp;  // the capture instant is the truth instant rendered
      frame.index = index++;
      const camera::FrameResult result = pipeline_->process(frame);
      frames_.fetch_add(1);
      detections_writer_.write(camera::to_tag_detections_msg(result, sensor_id_, "camera", "tag36h11", seq));
      if (result.world.valid) {
        pose_writer_.write(camera::to_vision_pose_msg(result, sensor_id_, seq));
        poses_.fetch_add(1);
      }
      ++seq;
    }
  }

  SimCameraParams p_;
  std::string sensor_id_;
  camera::CameraIntrinsics intrinsics_;
  std::vector<camera::SceneTag> scene_;
  Eigen::Isometry3d T_body_camera_ = Eigen::Isometry3d::Identity();
  std::unique_ptr<camera::CameraPipeline> pipeline_;
  std::unique_ptr<camera::SceneRenderer> renderer_;
  dds::Writer<msg::TagDetectionsPubSubType> detections_writer_;
  dds::Writer<msg::VisionPosePubSubType> pose_writer_;
  std::unique_ptr<dds::Reader<msg::PoseEstimatePubSubType>> truth_reader_;
  std::mutex mutex_;
  std::optional<Eigen::Isometry3d> latest_;
  int64_t latest_stamp_ns_ = 0;
  int64_t start_ns_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> frames_{0};
  std::atomic<uint64_t> poses_{0};
  std::atomic<uint64_t> blacked_out_{0};
  std::thread thread_;
};

}  // namespace

void register_sim_camera(runtime::ComponentRegistry& registry) {
  registry.add({"sim_camera",
                "Synthetic camera seeing floor AprilTags from the simulated truth (real detection pipeline)",
                [](const runtime::ComponentSpec& spec, runtime::HostContext& host) {
                  return std::make_unique<SimCamera>(spec, host);
                }});
}

}  // namespace poise::simulated
