#include "poise/camera/tag_map.h"
#include "poise/core/yaml_params.h"

#include "poise/camera/detector.h"
#include "poise/camera/intrinsics.h"  // ConfigError

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <vector>

namespace poise::camera {
namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
constexpr double kQuaternionNormTolerance = 1e-3;  // |q| must be 1 within this (no silent repair)
constexpr double kMaxTagSizeM = 10.0;

std::vector<double> numbers(const YAML::Node& node, std::size_t n, const std::string& what) {
  if (!node.IsSequence() || node.size() != n) {
    throw ConfigError(what + " must be a list of " + std::to_string(n) + " numbers");
  }
  std::vector<double> out;
  for (const auto& v : node) {
    const double x = v.as<double>();
    if (!std::isfinite(x)) {
      throw ConfigError(what + " has a non-finite value");
    }
    out.push_back(x);
  }
  return out;
}

}  // namespace

TagMap parse_tag_map(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = parse_yaml<ConfigError>(yaml_text, source);
  if (!root.IsMap() || !root["tags"] || !root["tags"].IsSequence()) {
    throw ConfigError(source + ": expected a map with a 'tags' list (see docs/CAMERA.md)");
  }
  TagMap map;
  try {
    if (root["family"]) {
      map.family = root["family"].as<std::string>();
    }
    double default_size = 0.0;
    if (root["default_size_m"]) {
      default_size = root["default_size_m"].as<double>();
    }
    std::size_t index = 0;
    for (const auto& node : root["tags"]) {
      const std::string where = source + ": tags[" + std::to_string(index++) + "]";
      if (!node.IsMap() || !node["id"]) {
        throw ConfigError(where + ": missing 'id'");
      }
      MappedTag tag;
      tag.id = node["id"].as<int>();
      const std::string tag_where = where + " (id " + std::to_string(tag.id) + ")";
      if (tag.id < 0) {
        throw ConfigError(tag_where + ": id must be >= 0");
      }
      if (map.tags.count(tag.id) != 0) {
        throw ConfigError(tag_where + ": duplicate id");
      }
      tag.size_m = node["size_m"] ? node["size_m"].as<double>() : default_size;
      if (!(tag.size_m > 0.0 && tag.size_m < kMaxTagSizeM)) {
        throw ConfigError(tag_where + ": size_m missing or not in (0, 10) m (give size_m or "
                                      "default_size_m: the black square's edge)");
      }
      if (!node["position_m"]) {
        throw ConfigError(tag_where + ": missing position_m [x, y, z] (world ENU, m)");
      }
      const auto p = numbers(node["position_m"], 3, tag_where + ": position_m");
      tag.T_world_tag.translation() = Eigen::Vector3d(p[0], p[1], p[2]);
      const bool has_q = static_cast<bool>(node["q_world_tag"]);
      const bool has_rpy = static_cast<bool>(node["rpy_deg"]);
      if (has_q == has_rpy) {
        throw ConfigError(tag_where + ": give exactly one of q_world_tag [w, x, y, z] or "
                                      "rpy_deg [roll, pitch, yaw]");
      }
      if (has_q) {
        const auto q = numbers(node["q_world_tag"], 4, tag_where + ": q_world_tag");
        Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
        if (std::abs(quat.norm() - 1.0) > kQuaternionNormTolerance) {
          throw ConfigError(tag_where + ": q_world_tag has norm " + std::to_string(quat.norm()) +
                            ", expected a unit quaternion [w, x, y, z]");
        }
        tag.T_world_tag.linear() = quat.normalized().toRotationMatrix();
      } else {
        const auto rpy = numbers(node["rpy_deg"], 3, tag_where + ": rpy_deg");
        tag.T_world_tag.linear() =
            (Eigen::AngleAxisd(rpy[2] * kDegToRad, Eigen::Vector3d::UnitZ()) *
             Eigen::AngleAxisd(rpy[1] * kDegToRad, Eigen::Vector3d::UnitY()) *
             Eigen::AngleAxisd(rpy[0] * kDegToRad, Eigen::Vector3d::UnitX()))
                .toRotationMatrix();
      }
      map.tags.emplace(tag.id, tag);
    }
  } catch (const YAML::Exception& e) {
    throw ConfigError(source + ": malformed value: " + e.what());
  }
  if (map.tags.empty()) {
    throw ConfigError(source + ": the tag map has no tags");
  }
  if (!map.family.empty()) {
    check_tag_map_family(map, map.family, source);
  }
  return map;
}

void check_tag_map_family(const TagMap& map, const std::string& family, const std::string& source) {
  if (!map.family.empty() && map.family != family) {
    throw ConfigError(source + ": the tag map is for family " + map.family + " but the detector looks for " +
                      family + ": set detector.family or fix the map");
  }
  const std::size_t codes = tag_family_layout(family).codes.size();
  for (const auto& [id, tag] : map.tags) {
    if (static_cast<std::size_t>(id) >= codes) {
      throw ConfigError(source + ": tag id " + std::to_string(id) + " does not exist in " + family + " (ids 0.." +
                        std::to_string(codes - 1) + "): it could never be detected");
    }
  }
}

TagMap load_tag_map(const std::string& path) {
  return parse_tag_map(read_yaml_text<ConfigError>(path, "cannot read tag map '" + path + "': check the path"), path);
}

}  // namespace poise::camera
