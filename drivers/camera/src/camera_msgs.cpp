#include "poise/camera/camera_msgs.h"

#include "poise/dds/convert.h"

namespace poise::camera {
namespace {

msg::Pose to_pose_msg(const Eigen::Isometry3d& t) {
  msg::Pose p;
  p.position_m(dds::to_msg(Eigen::Vector3d(t.translation())));
  p.orientation(dds::to_msg(Eigen::Quaterniond(t.linear()).normalized()));
  return p;
}

}  // namespace

msg::TagDetections to_tag_detections_msg(const FrameResult& result, const std::string& sensor_id,
                                         const std::string& frame_id, const std::string& family,
                                         uint32_t seq, uint64_t* truncated) {
  msg::TagDetections m;
  m.header(dds::make_header(result.stamp_ns, seq, frame_id));
  m.sensor_id(sensor_id);
  m.image_width_px(static_cast<uint32_t>(result.width_px));
  m.image_height_px(static_cast<uint32_t>(result.height_px));
  for (const auto& d : result.detections) {
    if (m.detections().size() >= kMaxTagsPerMessage) {
      if (truncated != nullptr) {
        ++*truncated;
      }
      continue;
    }
    msg::TagDetection t;
    t.id(d.detection.id);
    t.family(family);
    t.hamming(d.detection.hamming);
    t.decision_margin(d.detection.decision_margin);
    for (std::size_t c = 0; c < 4; ++c) {
      msg::Point2 p;
      p.x_px(d.detection.corners_px[c].x());
      p.y_px(d.detection.corners_px[c].y());
      t.corners()[c] = p;
    }
    t.pose_valid(d.pose_computed && d.pose.valid);
    t.pose_camera_tag(to_pose_msg(d.pose_computed ? d.pose.best.T_camera_tag
                                                  : Eigen::Isometry3d::Identity()));
    t.tag_size_m(d.size_m);
    t.reprojection_error_px(d.pose_computed ? d.pose.best.reprojection_rms_px : 0.0);
    t.ambiguity_ratio(d.pose_computed ? d.pose.ambiguity_ratio : 0.0);
    t.in_map(d.in_map);
    m.detections().push_back(t);
  }
  return m;
}

msg::VisionPose to_vision_pose_msg(const FrameResult& result, const std::string& sensor_id,
                                   uint32_t seq) {
  msg::VisionPose m;
  m.header(dds::make_header(result.stamp_ns, seq, "world"));
  m.sensor_id(sensor_id);
  m.capture_stamp_ns(result.stamp_ns);
  m.pose_world_camera(to_pose_msg(result.world.T_world_camera));
  m.body_valid(result.body_valid);
  m.pose_world_body(to_pose_msg(result.body_valid ? result.T_world_body
                                                  : result.world.T_world_camera));
  const Eigen::Matrix<double, 6, 6>& cov =
      result.body_valid ? result.covariance_body : result.world.covariance;
  dds::to_array<6, 6, 36>(cov, m.covariance());
  m.reprojection_rms_px(result.world.reprojection_rms_px);
  std::vector<int32_t> ids;
  for (int id : result.world.tag_ids) {
    if (ids.size() < kMaxTagsPerMessage) {
      ids.push_back(id);
    }
  }
  m.tag_ids(ids);
  return m;
}

}  // namespace poise::camera
