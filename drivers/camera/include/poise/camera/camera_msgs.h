// Pure conversions from pipeline results to the vision IDL messages (idl/vision.idl).
#pragma once

#include "poise/camera/pipeline.h"

#include <poise/msg/vision.h>

#include <cstdint>
#include <string>

namespace poise::camera {

/// IDL bound of TagDetections.detections and VisionPose.tag_ids.
inline constexpr std::size_t kMaxTagsPerMessage = 64;

/// All detections of a frame (corners distorted, library order; per-tag pose when computed and
/// not rejected). Detections beyond the IDL bound are dropped; `truncated` (if given) counts them.
msg::TagDetections to_tag_detections_msg(const FrameResult& result, const std::string& sensor_id,
                                         const std::string& frame_id, const std::string& family,
                                         uint32_t seq, uint64_t* truncated = nullptr);

/// The world pose of a frame (call only when result.world.valid). Covariance is the body's when
/// body_valid, else the camera's; frame_id "world".
msg::VisionPose to_vision_pose_msg(const FrameResult& result, const std::string& sensor_id,
                                   uint32_t seq);

}  // namespace poise::camera
