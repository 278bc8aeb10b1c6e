// Component `sim_camera`: a synthetic camera that sees AprilTags on the floor from the simulated
// truth. It follows `truth/pose` (published by sim_imu), renders the tag scene from the true
// camera pose (body pose x camera extrinsic) with the family's real codes, runs the real camera
// pipeline (libapriltag detection, IPPE, joint world pose, covariance) and publishes
// `tag_detections` and `vision_pose` stamped at the capture (truth) instant, so they arrive late
// by the real processing time, as from a real camera.
//
// Parameters: fps (10), width_px (640), height_px (480), focal_px (460), tag_size_m (0.24),
// tag_spacing_m (0.7), floor_z_m (-1.2: tags on a 3x3 grid on the floor below the start),
// blackouts ([[start_s, end_s], ...]: no frames, e.g. the tag leaving the view),
// blackout_period_s (repeat the blackouts every period; 30 = the `tour` scenario cycle; 0 = once),
// noise (grey levels, 2), seed (1), pixel_sigma_px (the pipeline's prior corner noise, px; its
// default 0.25 unless told: `poise demo` and config/hosts/simulated.yaml give this render's own
// figure, 0.08 px, docs/CAMERA.md "Finding pixel_sigma_px"). Its pipeline takes the corners' edge-line noise
// model (pose.corner_noise edges: measured on its renders).
// Camera extrinsic: looking down through the body's -z (camera x = body x, y = -body y,
// z = -body z).
#pragma once

#include "poise/runtime/component.h"

namespace poise::simulated {
void register_sim_camera(runtime::ComponentRegistry& registry);
}  // namespace poise::simulated
