// `poise camera`: run the camera component alone (one process), publishing tag_detections and
// vision_pose until Ctrl-C, --duration, or the end of a file/list/synthetic source.
#include "poise/camera/camera_node.h"
#include "poise/cli/common.h"
#include "poise/runtime/shipped.h"

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <memory>
#include <thread>

namespace poise::cli {
namespace {

struct CameraCliOptions {
  std::string source;
  std::string intrinsics;
  std::string tags;
  std::string config;
  std::string name;
  std::string profile;
  int domain = 0;
  double duration_s = 0.0;
  double status_period_s = 2.0;
  double capture_delay_ms = -1.0;
  bool fast = false;
  bool quiet = false;
};

void run_camera(const CameraCliOptions& o) {
  runtime::ComponentSpec spec;
  spec.type = "camera";
  spec.name = o.name;
  spec.origin = "poise camera";
  spec.params = YAML::Node(YAML::NodeType::Map);
  spec.params["source"] = o.source;
  spec.params["intrinsics_file"] = o.intrinsics;
  spec.params["tags_file"] = o.tags;
  if (!o.config.empty()) {
    spec.params["config_file"] = o.config;
  }
  spec.params["pace"] = !o.fast;
  spec.params["diagnostics_period_s"] = o.status_period_s;
  if (o.capture_delay_ms >= 0.0) {
    spec.params["capture_delay_ms"] = o.capture_delay_ms;
  }
  install_stop_handlers();
  std::unique_ptr<dds::Participant> participant;
  std::unique_ptr<runtime::HostContext> context;
  std::unique_ptr<camera::CameraNode> node;
  try {
    camera::CameraNodeOptions options = camera::camera_node_options(spec);
    options.log_to_stderr = !o.quiet;
    dds::ParticipantOptions po;
    po.domain = o.domain;
    po.profile = o.profile;
    po.name = "poise camera";
    participant = std::make_unique<dds::Participant>(po);
    context = std::make_unique<runtime::HostContext>(runtime::HostContext{*participant, {}});
    node = std::make_unique<camera::CameraNode>(options, o.name, *context);
  } catch (const runtime::ConfigError& e) {
    throw Error(e.what());
  } catch (const dds::DdsError& e) {
    throw Error(e.what());
  }
  node->start();
  if (!o.quiet) {
    std::fprintf(stderr,
                 "poise camera: %s -> 'tag_detections' + 'vision_pose' as %s (domain %d); "
                 "Ctrl-C stops\n",
                 o.source.c_str(), node->sensor_id().c_str(), o.domain);
  }
  const auto start = std::chrono::steady_clock::now();
  auto next_status = start + std::chrono::duration<double>(o.status_period_s);
  while (!stop_requested() && !node->finished()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const auto now = std::chrono::steady_clock::now();
    if (o.duration_s > 0 && std::chrono::duration<double>(now - start).count() >= o.duration_s) {
      break;
    }
    if (!o.quiet && now >= next_status) {
      std::fprintf(stderr, "  %s\n", node->status().c_str());
      next_status += std::chrono::duration<double>(o.status_period_s);
    }
  }
  node->stop();
  const bool failed = node->failed();
  const std::string error = node->error();
  if (!o.quiet) {
    std::fprintf(stderr, "poise camera: stopped after %llu frames, %llu poses published\n",
                 static_cast<unsigned long long>(node->frames()),
                 static_cast<unsigned long long>(node->poses_published()));
  }
  node.reset();
  context.reset();
  participant.reset();
  if (failed) {
    throw Error(error);
  }
}

}  // namespace

void register_camera_node_cli(CLI::App& app) {
  auto o = std::make_shared<CameraCliOptions>();
  CLI::App* cmd = app.add_subcommand(
      "camera", "AprilTag camera: capture, detect, and publish tag_detections and vision_pose "
                "(camera/body pose in the world from a tag map) stamped at capture time");
  cmd->add_option("--source", o->source,
                  "/dev/videoN | v4l2:N | video file | image, directory or quoted glob | "
                  "synthetic[:frames=N,fps=F,seed=S,noise=G,blur=B]")
      ->required();
  cmd->add_option("--intrinsics", o->intrinsics, "OpenCV calibration or ROS camera_info YAML")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--tags", o->tags, "Tag map YAML (see " + runtime::shipped_file_hint("camera/tags_example.yaml") + ")")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--config", o->config, "Camera config YAML (see " + runtime::shipped_file_hint("camera/camera.yaml") + ")")
      ->check(CLI::ExistingFile);
  cmd->add_option("--name", o->name, "sensor_id of the published samples (default: the config's)");
  add_dds_profile_option(cmd, &o->profile);
  add_deprecated_alias(cmd, "--profile", "--dds-profile", &o->profile);
  add_domain_option(cmd, &o->domain);
  cmd->add_option("--duration", o->duration_s, "Stop after this many seconds (0: until Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--status-period", o->status_period_s, "Seconds between status lines")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--capture-delay-ms", o->capture_delay_ms,
                  "Stamp frames this long before their grab (exposure + transfer; overrides the "
                  "config's capture.delay_ms): the camera's prior of its time offset to the IMU, the "
                  "selective EKF estimates what is left (vision_time_offset_sigma_s), ms in [0, 1000)")
      ->check(CLI::Range(0.0, 999.999));
  cmd->add_flag("--fast", o->fast, "Synthetic source: render as fast as possible (no pacing)");
  cmd->add_flag("--quiet", o->quiet, "No status output");
  cmd->callback([o] { run_camera(*o); });
}

}  // namespace poise::cli
