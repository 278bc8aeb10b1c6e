// Tag map: which tags exist in the world, their size and pose (YAML, see docs/CAMERA.md).
//
//   family: tag36h11              # optional; must match the detector's family when given
//   default_size_m: 0.16          # optional; used by tags without size_m
//   tags:
//     - id: 0
//       size_m: 0.16              # edge of the detected square (tag36h11: the black square), m
//       position_m: [0, 2, 1.5]   # tag centre in the world (ENU), m
//       q_world_tag: [0.70710678, 0.70710678, 0, 0]   # Hamilton [w, x, y, z]
//       # or rpy_deg: [roll, pitch, yaw]   (R_world_tag = Rz(yaw) Ry(pitch) Rx(roll))
//
// Tag frame: origin at the tag centre, x to the tag's right, y up (towards pattern row 0), z out of
// the printed face. A tag flat on the floor, readable from the south: identity. A tag on a wall,
// facing south: rpy_deg [90, 0, 0].
#pragma once

#include <Eigen/Geometry>

#include <map>
#include <optional>
#include <string>

namespace poise::camera {

struct MappedTag {
  int id = 0;
  double size_m = 0.0;
  Eigen::Isometry3d T_world_tag = Eigen::Isometry3d::Identity();
};

struct TagMap {
  std::string family;  ///< empty = not stated
  std::map<int, MappedTag> tags;

  [[nodiscard]] const MappedTag* find(int id) const {
    const auto it = tags.find(id);
    return it == tags.end() ? nullptr : &it->second;
  }
};

/// Loads and validates a tag map. Throws ConfigError with the file and the offending entry.
TagMap load_tag_map(const std::string& path);
TagMap parse_tag_map(const std::string& yaml_text, const std::string& source);

/// Throws ConfigError "<source>: tag id N does not exist in <family> (ids 0..M-1)" when the map
/// names an id the family does not have (it could never be detected), or when the map states a
/// family other than `family`. parse_tag_map() applies it to a map that states its family; the
/// pipeline to every map against the detector's family.
void check_tag_map_family(const TagMap& map, const std::string& family, const std::string& source);

}  // namespace poise::camera
