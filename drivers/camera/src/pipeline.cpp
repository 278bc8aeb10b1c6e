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

double elapsed_ms(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

CameraConfig parse_camera_config(const std::string& yaml_text, const std::string& source) {
  using Reader = BasicYamlParamReader<ConfigError>;
  CameraConfig c;
  Reader r(parse_yaml<ConfigError>(yaml_text, source), source);
  r.get("sensor_id", c.sensor_id);
  r.get("frame_id", c.frame_id);

  Reader cap = r.child("capture");
  cap.get_scaled("delay_ms", c.capture_delay_s, 1e-3);
  cap.get("width_px", c.width_px);
  cap.get("height_px", c.height_px);
  cap.get("fps", c.fps);
  cap.get("max_image_pixels", c.max_image_pixels);
  cap.finish();

  Reader det = r.child("detector");
  det.get("family", c.detector.family);
  det.get("decimate", c.detector.decimate);
  det.get("blur_sigma_px", c.detector.blur_sigma);
  det.get("threads", c.detector.threads);
  det.get("refine_edges", c.detector.refine_edges);
  det.get("decode_sharpening", c.detector.decode_sharpening);
  det.get("max_hamming", c.detector.max_hamming);
  det.get("min_decision_margin", c.detector.min_decision_margin);
  det.finish();

  Reader pose = r.child("pose");
  pose.get("ambiguity_ratio_max", c.tag_pose.ambiguity_ratio_max);
  pose.get_scaled("ambiguity_min_angle_deg", c.tag_pose.ambiguity_min_angle_rad, kDegToRad);
  pose.get("max_tag_reprojection_px", c.tag_pose.max_reprojection_rms_px);
  pose.get("max_world_reprojection_px", c.world_pose.max_reprojection_rms_px);
  pose.get("pixel_sigma_px", c.world_pose.pixel_sigma_px);
  pose.get("pixel_sigma_dof", c.world_pose.pixel_sigma_dof);
  if (pose.given("corner_noise")) {
    std::string model;
    pose.get("corner_noise", model);
    if (model == "edges") {
      c.world_pose.corner_noise = CornerNoise::kEdgeLines;
    } else if (model == "white") {
      c.world_pose.corner_noise = CornerNoise::kWhite;
    } else {
      throw ConfigError(source + ": pose.corner_noise must be edges or white (got '" + model + "')");
    }
  }
  pose.get("max_iterations", c.world_pose.max_iterations);
  pose.get("unknown_tag_size_m", c.unknown_tag_size_m);
  pose.finish();

  if (r.has("extrinsic")) {
    Reader ext = r.child("extrinsic");
    if (!ext.given("position_m") || !ext.given("q_body_camera")) {
      throw ConfigError(source + ": extrinsic needs position_m [x, y, z] (camera origin in the "
                                 "body frame, m) and q_body_camera [w, x, y, z]");
    }
    Eigen::Vector3d p(0.0, 0.0, 0.0);
    ext.get("position_m", p);
    Eigen::Vector4d q(1.0, 0.0, 0.0, 0.0);
    ext.get("q_body_camera", q);
    ext.finish();
    const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
    if (!std::isfinite(quat.norm()) || std::abs(quat.norm() - 1.0) > 1e-3) {
      throw ConfigError(source + ": extrinsic q_body_camera is not a unit quaternion");
    }
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = quat.normalized().toRotationMatrix();
    t.translation() = p;
    if (!t.translation().allFinite()) {
      throw ConfigError(source + ": extrinsic position_m is not finite");
    }
    c.T_body_camera = t;
  }
  r.finish();
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
  return parse_camera_config(read_yaml_text<ConfigError>(path, "cannot read camera config '" + path + "'"), path);
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
