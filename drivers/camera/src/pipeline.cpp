#include "poise/camera/pipeline.h"
#include "poise/core/yaml_params.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

namespace poise::camera {
namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

void check_keys(const YAML::Node& node, const std::set<std::string>& allowed,
                const std::string& where) {
  if (!node.IsMap()) {
    throw ConfigError(where + " must be a map");
  }
  for (const auto& kv : node) {
    const auto key = kv.first.as<std::string>();
    if (allowed.count(key) == 0) {
      std::string list;
      for (const auto& a : allowed) {
        list += (list.empty() ? "" : ", ") + a;
      }
      throw ConfigError(where + ": unknown key '" + key + "' (known: " + list + ")");
    }
  }
}

template <typename T>
void read(const YAML::Node& node, const char* key, T* value) {
  if (node[key]) {
    *value = node[key].as<T>();
  }
}

double elapsed_ms(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

CameraConfig parse_camera_config(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = parse_yaml<ConfigError>(yaml_text, source);
  CameraConfig c;
  if (root.IsNull()) {
    return c;
  }
  try {
    check_keys(root, {"sensor_id", "frame_id", "capture", "detector", "pose", "extrinsic"}, source);
    read(root, "sensor_id", &c.sensor_id);
    read(root, "frame_id", &c.frame_id);
    if (const auto cap = root["capture"]) {
      check_keys(cap, {"delay_ms", "width_px", "height_px", "fps", "max_image_pixels"}, source + ": capture");
      double delay_ms = c.capture_delay_s * 1e3;
      read(cap, "delay_ms", &delay_ms);
      c.capture_delay_s = delay_ms * 1e-3;
      read(cap, "width_px", &c.width_px);
      read(cap, "height_px", &c.height_px);
      read(cap, "fps", &c.fps);
      read(cap, "max_image_pixels", &c.max_image_pixels);
    }
    if (const auto det = root["detector"]) {
      check_keys(det,
                 {"family", "decimate", "blur_sigma_px", "threads", "refine_edges",
                  "decode_sharpening", "max_hamming", "min_decision_margin"},
                 source + ": detector");
      read(det, "family", &c.detector.family);
      read(det, "decimate", &c.detector.decimate);
      read(det, "blur_sigma_px", &c.detector.blur_sigma);
      read(det, "threads", &c.detector.threads);
      read(det, "refine_edges", &c.detector.refine_edges);
      read(det, "decode_sharpening", &c.detector.decode_sharpening);
      read(det, "max_hamming", &c.detector.max_hamming);
      read(det, "min_decision_margin", &c.detector.min_decision_margin);
    }
    if (const auto pose = root["pose"]) {
      check_keys(pose,
                 {"ambiguity_ratio_max", "ambiguity_min_angle_deg", "max_tag_reprojection_px",
                  "max_world_reprojection_px", "pixel_sigma_px", "max_iterations",
                  "unknown_tag_size_m"},
                 source + ": pose");
      read(pose, "ambiguity_ratio_max", &c.tag_pose.ambiguity_ratio_max);
      double angle_deg = c.tag_pose.ambiguity_min_angle_rad / kDegToRad;
      read(pose, "ambiguity_min_angle_deg", &angle_deg);
      c.tag_pose.ambiguity_min_angle_rad = angle_deg * kDegToRad;
      read(pose, "max_tag_reprojection_px", &c.tag_pose.max_reprojection_rms_px);
      read(pose, "max_world_reprojection_px", &c.world_pose.max_reprojection_rms_px);
      read(pose, "pixel_sigma_px", &c.world_pose.pixel_sigma_px);
      read(pose, "max_iterations", &c.world_pose.max_iterations);
      read(pose, "unknown_tag_size_m", &c.unknown_tag_size_m);
    }
    if (const auto ext = root["extrinsic"]) {
      check_keys(ext, {"position_m", "q_body_camera"}, source + ": extrinsic");
      if (!ext["position_m"] || !ext["q_body_camera"]) {
        throw ConfigError(source + ": extrinsic needs position_m [x, y, z] (camera origin in the "
                                   "body frame, m) and q_body_camera [w, x, y, z]");
      }
      const auto p = ext["position_m"].as<std::vector<double>>();
      const auto q = ext["q_body_camera"].as<std::vector<double>>();
      if (p.size() != 3 || q.size() != 4) {
        throw ConfigError(source + ": extrinsic position_m needs 3 values, q_body_camera 4");
      }
      const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
      if (!std::isfinite(quat.norm()) || std::abs(quat.norm() - 1.0) > 1e-3) {
        throw ConfigError(source + ": extrinsic q_body_camera is not a unit quaternion");
      }
      Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
      t.linear() = quat.normalized().toRotationMatrix();
      t.translation() = Eigen::Vector3d(p[0], p[1], p[2]);
      if (!t.translation().allFinite()) {
        throw ConfigError(source + ": extrinsic position_m is not finite");
      }
      c.T_body_camera = t;
    }
  } catch (const YAML::Exception& e) {
    throw ConfigError(source + ": malformed value: " + e.what());
  }
  c.world_pose.ambiguity_ratio_max = c.tag_pose.ambiguity_ratio_max;
  c.world_pose.ambiguity_min_angle_rad = c.tag_pose.ambiguity_min_angle_rad;
  if (!(c.capture_delay_s >= 0.0 && c.capture_delay_s < 1.0)) {
    throw ConfigError(source + ": capture.delay_ms must be in [0, 1000)");
  }
  if (c.width_px < 0 || c.height_px < 0 || !(c.fps >= 0.0)) {
    throw ConfigError(source + ": capture width/height/fps must be >= 0");
  }
  if (c.max_image_pixels < 1 || c.max_image_pixels > (int64_t{1} << 30)) {
    throw ConfigError(source + ": capture.max_image_pixels must be in [1, 2^30]");
  }
  if (!(c.unknown_tag_size_m >= 0.0)) {
    throw ConfigError(source + ": pose.unknown_tag_size_m must be >= 0");
  }
  try {
    validate_detector_params(c.detector);
    validate_tag_pose_params(c.tag_pose);
    validate_world_pose_params(c.world_pose);
  } catch (const ConfigError& e) {
    throw ConfigError(source + ": " + e.what());
  }
  return c;
}

CameraConfig load_camera_config(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    throw ConfigError("cannot read camera config '" + path + "'");
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  return parse_camera_config(buffer.str(), path);
}

CameraPipeline::CameraPipeline(const CameraConfig& config, const CameraIntrinsics& intrinsics,
                               const TagMap& tag_map)
    : config_(config),
      intrinsics_(intrinsics),
      map_(tag_map),
      detector_(config.detector),
      k_(intrinsics.camera_matrix()),
      distortion_(intrinsics.distortion_mat()) {
  validate_intrinsics(intrinsics_, "intrinsics");
  check_tag_map_family(map_, config_.detector.family, "tag map");
}

void CameraPipeline::set_tag_map(const TagMap& tag_map) {
  check_tag_map_family(tag_map, config_.detector.family, "tag map");
  map_ = tag_map;
}

void CameraPipeline::set_world_pose_params(const WorldPoseParams& params) {
  validate_world_pose_params(params);
  config_.world_pose = params;
}

// not split: one frame through the pipeline in order (checks, detection, per-tag pose, world pose,
// timing), each stage's rejections counted where they happen.
FrameResult CameraPipeline::process(const Frame& frame) {
  const auto t0 = std::chrono::steady_clock::now();
  FrameResult out;
  out.stamp_ns = frame.stamp_ns;
  out.width_px = frame.image.cols;
  out.height_px = frame.image.rows;
  ++counters_["frames"];
  if (frame.image.cols != intrinsics_.width_px || frame.image.rows != intrinsics_.height_px) {
    throw ConfigError("frame is " + std::to_string(frame.image.cols) + "x" +
                      std::to_string(frame.image.rows) + " but the intrinsics are for " +
                      std::to_string(intrinsics_.width_px) + "x" +
                      std::to_string(intrinsics_.height_px) +
                      ": calibrate at this resolution or request it with capture.width_px/height_px");
  }
  const cv::Mat* gray = &frame.image;
  if (frame.image.type() == CV_8UC3) {
    cv::cvtColor(frame.image, gray_, cv::COLOR_BGR2GRAY);
    gray = &gray_;
  } else if (frame.image.type() == CV_8UC4) {
    cv::cvtColor(frame.image, gray_, cv::COLOR_BGRA2GRAY);
    gray = &gray_;
  } else if (frame.image.type() != CV_8UC1) {
    ++counters_["rejected_pixel_format"];
    out.world.reject_reason = "pixel_format";
    return out;
  }
  if (gray->cols < detector_.min_image_side_px() || gray->rows < detector_.min_image_side_px()) {
    ++counters_["rejected_image_size"];  // libapriltag crashes on images this small
    out.world.reject_reason = "image_size";
    return out;
  }
  const auto detections = detector_.detect(*gray);
  out.detect_ms = elapsed_ms(t0);
  if (!detections.empty()) {
    ++counters_["frames_with_tags"];
  }
  // Undistort all corners in one call.
  std::vector<cv::Point2d> distorted;
  distorted.reserve(detections.size() * 4);
  for (const auto& d : detections) {
    for (const auto& c : d.corners_px) {
      distorted.emplace_back(c.x(), c.y());
    }
  }
  std::vector<cv::Point2d> ideal;
  if (!distorted.empty()) {
    if (distortion_.empty()) {
      ideal = distorted;
    } else {
      cv::undistortPoints(distorted, ideal, k_, distortion_, cv::noArray(), k_);
    }
  }
  std::vector<TagObservation> observations;
  out.detections.reserve(detections.size());
  for (std::size_t i = 0; i < detections.size(); ++i) {
    DetectionResult r;
    r.detection = detections[i];
    for (std::size_t c = 0; c < 4; ++c) {
      r.ideal_px[c] = {ideal[i * 4 + c].x, ideal[i * 4 + c].y};
    }
    const MappedTag* mapped = map_.find(r.detection.id);
    r.in_map = mapped != nullptr;
    r.size_m = mapped != nullptr ? mapped->size_m : config_.unknown_tag_size_m;
    if (!r.in_map) {
      ++counters_["detections_not_in_map"];
    }
    if (r.size_m > 0.0) {
      r.pose = estimate_tag_pose(r.ideal_px, r.size_m, k_, config_.tag_pose);
      r.pose_computed = true;
      if (r.pose.ambiguous) {
        ++counters_["tag_pose_ambiguous"];
      }
      if (r.pose.reprojection_too_large) {
        ++counters_["tag_pose_reprojection"];
      }
    }
    if (r.in_map) {
      TagObservation obs;
      obs.tag = mapped;
      obs.corners_px = r.ideal_px;
      obs.pose = r.pose;
      observations.push_back(obs);
    }
    out.detections.push_back(r);
  }
  if (observations.empty()) {
    out.world.reject_reason = "no_mapped_tags";
    ++counters_["world_no_mapped_tags"];
  } else {
    out.world = estimate_world_pose(observations, k_, config_.world_pose);
    if (out.world.valid) {
      ++counters_["world_pose_ok"];
      if (config_.T_body_camera) {
        camera_to_body(out.world.T_world_camera, out.world.covariance, *config_.T_body_camera,
                       &out.T_world_body, &out.covariance_body);
        out.body_valid = true;
      }
    } else {
      ++counters_["world_rejected_" + out.world.reject_reason];
    }
  }
  out.total_ms = elapsed_ms(t0);
  return out;
}

PoseMeasurement CameraPipeline::to_measurement(const FrameResult& result) {
  PoseMeasurement m;
  m.stamp_ns = result.stamp_ns;
  const Eigen::Isometry3d& t = result.body_valid ? result.T_world_body : result.world.T_world_camera;
  m.p_world_body_m = t.translation();
  m.q_world_body = Eigen::Quaterniond(t.linear()).normalized();
  m.covariance = result.body_valid ? result.covariance_body : result.world.covariance;
  return m;
}

}  // namespace poise::camera
