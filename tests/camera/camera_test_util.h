// Shared fixtures for the camera tests: a 640x480 camera, scenes, error metrics.
#pragma once

#include "poise/camera/intrinsics.h"
#include "poise/camera/renderer.h"
#include "poise/camera/tag_map.h"

#include <Eigen/Geometry>

#include <cmath>

namespace poise::camera::testing {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

/// A 640x480 camera with ~65 deg horizontal field of view and mild barrel distortion.
inline CameraIntrinsics vga_camera(bool distorted = true) {
  CameraIntrinsics k;
  k.width_px = 640;
  k.height_px = 480;
  k.fx_px = 500.0;
  k.fy_px = 498.0;
  k.cx_px = 321.3;
  k.cy_px = 238.7;
  if (distorted) {
    k.distortion = {-0.12, 0.05, 0.0007, -0.0004, 0.0};
  }
  return k;
}

/// Pose of a tag facing the camera: the camera at the world origin looking along +y (north), the
/// tag `distance_m` ahead, turned by yaw about world z and pitched about its own x, centre offset
/// laterally by (dx, dz).
inline SceneTag tag_ahead(int id, double size_m, double distance_m, double yaw_rad = 0.0,
                          double pitch_rad = 0.0, double dx_m = 0.0, double dz_m = 0.0) {
  SceneTag t;
  t.id = id;
  t.size_m = size_m;
  // Facing south (towards the camera): rpy (90, 0, 180) puts z_tag = -y, x_tag = -x... use a
  // wall tag facing south (Rx(+90)) rotated by yaw and pitch.
  const Eigen::Matrix3d facing_south = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  t.T_world_tag.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                           facing_south *
                           Eigen::AngleAxisd(pitch_rad, Eigen::Vector3d::UnitX()).toRotationMatrix();
  t.T_world_tag.translation() = Eigen::Vector3d(dx_m, distance_m, dz_m);
  return t;
}

/// The camera at the origin looking north, image up = world up.
inline Eigen::Isometry3d camera_at_origin_looking_north() {
  return look_at(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ());
}

inline double angle_between(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

inline TagMap map_of(const std::vector<SceneTag>& tags, const std::string& family = "tag36h11") {
  TagMap m;
  m.family = family;
  for (const auto& t : tags) {
    m.tags[t.id] = MappedTag{t.id, t.size_m, t.T_world_tag};
  }
  return m;
}

}  // namespace poise::camera::testing
