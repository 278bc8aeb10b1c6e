#include "poise/foxglove/panels.h"

#include <nlohmann/json.hpp>

#include <cctype>
#include <cmath>

namespace poise::foxglove {

using nlohmann::json;

namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

std::string dump(const json& j) { return j.dump(-1, ' ', false, json::error_handler_t::replace); }

/// A numeric member at `path` as a double (NaN when absent or not a number).
double number(const schema::Value& v, const std::string& path) {
  const schema::Value* f = v.at(path);
  if (f == nullptr) {
    return std::nan("");
  }
  switch (f->kind) {
    case schema::Value::Kind::kFloat: return f->d;
    case schema::Value::Kind::kInt: return static_cast<double>(f->i);
    case schema::Value::Kind::kUInt: return static_cast<double>(f->u);
    case schema::Value::Kind::kBool: return f->b ? 1.0 : 0.0;
    default: return std::nan("");
  }
}

std::optional<std::int64_t> stamp_ns(const schema::Value& v) {
  const schema::Value* f = v.at("header.stamp_ns");
  if (f == nullptr || f->kind != schema::Value::Kind::kInt) {
    return std::nullopt;
  }
  return f->i;
}

/// {"sec","nsec"} of stamp + offset (floor division: nsec in [0, 1e9)); nullopt before 1970.
std::optional<json> time_json(std::int64_t stamp, std::int64_t offset_ns) {
  const std::int64_t t = stamp + offset_ns;
  if (t < 0) {
    return std::nullopt;
  }
  return json{{"sec", t / 1'000'000'000}, {"nsec", t % 1'000'000'000}};
}

/// A finite number, or null (JSON has no NaN).
json finite_or_null(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }

json vector_schema(const char* description) {
  return {{"type", "object"},
          {"description", description},
          {"properties", {{"x", {{"type", "number"}}}, {"y", {{"type", "number"}}}, {"z", {{"type", "number"}}}}}};
}

json time_schema() {
  return {{"type", "object"},
          {"title", "time"},
          {"properties",
           {{"sec", {{"type", "integer"}, {"minimum", 0}}},
            {"nsec", {{"type", "integer"}, {"minimum", 0}, {"maximum", 999999999}}}}}};
}

}  // namespace

const std::string& frame_transform_schema() {
  static const std::string text = dump(
      {{"title", kFrameTransformSchemaName},
       {"description", "A transform between two reference frames in 3D space"},
       {"type", "object"},
       {"properties",
        {{"timestamp", time_schema()},
         {"parent_frame_id", {{"type", "string"}, {"description", "Name of the parent frame"}}},
         {"child_frame_id", {{"type", "string"}, {"description", "Name of the child frame"}}},
         {"translation", vector_schema("Translation component of the transform, m")},
         {"rotation",
          {{"type", "object"},
           {"description", "Rotation component of the transform (q_parent_child)"},
           {"properties",
            {{"x", {{"type", "number"}}},
             {"y", {{"type", "number"}}},
             {"z", {{"type", "number"}}},
             {"w", {{"type", "number"}}}}}}}}}});
  return text;
}

const std::string& attitude_plot_schema() {
  static const std::string text = dump(
      {{"title", kAttitudePlotSchemaName},
       {"description", "One poise attitude estimate, for plots: angles, magnetic disturbance, trust"},
       {"type", "object"},
       {"properties",
        {{"timestamp", time_schema()},
         {"filter", {{"type", "string"}}},
         {"rpy_deg", vector_schema("ZYX roll (x), pitch (y), yaw (z, from east, ENU), deg")},
         {"mag_disturbance_world_ut", vector_schema("estimated magnetic disturbance, world frame (ENU), uT")},
         {"mag_disturbance_norm_ut", {{"type", "number"}, {"description", "its norm, uT"}}},
         {"mag_disturbance_angle_deg",
          {{"type", "number"}, {"description", "|measured dip - reference dip|, deg"}}},
         {"mag_trusted",
          {{"type", "integer"}, {"description", "1 when the magnetometer was used for heading, else 0"}}},
         {"heading_status",
          {{"type", "string"},
           {"description", "verified | unverified | no_reference: is the heading backed by a trusted field "
                           "(AttitudeEstimate.heading_status)"}}},
         {"heading_verified", {{"type", "integer"}, {"description", "1 when heading_status is verified, else 0"}}},
         {"yaw_sigma_deg",
          {{"type", "number"}, {"description", "square root of the published covariance's yaw (zz) element, deg"}}}}}});
  return text;
}

double FrameLayout::offset_m(const std::string& frame) {
  static const std::map<std::string, int> fixed{
      {"truth", 0}, {"parallel_kf", 1}, {"selective_ekf", 2}, {"gauss_newton", 3}, {"vehicle", 4}};
  const auto f = fixed.find(frame);
  int slot = 0;
  if (f != fixed.end()) {
    slot = f->second;
  } else {
    const auto e = extra_.find(frame);
    slot = e != extra_.end() ? e->second
                             : extra_.emplace(frame, static_cast<int>(fixed.size() + extra_.size())).first->second;
  }
  return spacing_m_ * slot;
}

std::string child_frame(const std::string& topic) {
  auto starts = [&topic](const std::string& prefix) { return topic.rfind(prefix, 0) == 0 && topic.size() > prefix.size(); };
  if (topic == "truth/attitude") {
    return "truth";
  }
  if (topic == "truth/pose") {
    return "truth_pose";
  }
  if (topic == "vision_pose") {
    return "camera";
  }
  if (starts("attitude/")) {
    return topic.substr(9);
  }
  if (starts("pose/")) {
    return topic.substr(5) + "_pose";
  }
  std::string out = topic;
  for (char& c : out) {
    if (c == '/') {
      c = '_';
    }
  }
  return out;
}

std::optional<std::string> frame_transform_json(const std::string& type, const schema::Value& message,
                                                const std::string& parent_frame, const std::string& child,
                                                double offset_x_m, std::int64_t offset_ns) {
  std::string q_path = "q_world_body";
  std::string p_path;
  if (type == "poise::msg::PoseEstimate") {
    p_path = "position_m";
  } else if (type == "poise::msg::VisionPose") {
    q_path = "pose_world_camera.orientation";
    p_path = "pose_world_camera.position_m";
  } else if (type != "poise::msg::AttitudeEstimate") {
    return std::nullopt;
  }
  const auto stamp = stamp_ns(message);
  if (!stamp) {
    return std::nullopt;
  }
  const auto time = time_json(*stamp, offset_ns);
  const double w = number(message, q_path + ".w");
  const double x = number(message, q_path + ".x");
  const double y = number(message, q_path + ".y");
  const double z = number(message, q_path + ".z");
  const double norm = std::sqrt(w * w + x * x + y * y + z * z);
  double px = offset_x_m;
  double py = 0.0;
  double pz = 0.0;
  if (!p_path.empty()) {
    px = number(message, p_path + ".x");
    py = number(message, p_path + ".y");
    pz = number(message, p_path + ".z");
  }
  if (!time || !std::isfinite(norm) || norm < 1e-6 || !std::isfinite(px) || !std::isfinite(py) ||
      !std::isfinite(pz)) {
    return std::nullopt;
  }
  return dump({{"timestamp", *time},
               {"parent_frame_id", parent_frame},
               {"child_frame_id", child},
               {"translation", {{"x", px}, {"y", py}, {"z", pz}}},
               {"rotation", {{"x", x / norm}, {"y", y / norm}, {"z", z / norm}, {"w", w / norm}}}});
}

namespace {

/// heading_status as a word: the IDL enumerator without HEADING_, in lower case ("" when absent).
std::string heading_word(const schema::Value& attitude) {
  const schema::Value* v = attitude.at("heading_status");
  if (v == nullptr || v->kind != schema::Value::Kind::kEnum) {
    return "";
  }
  std::string word = v->s.rfind("HEADING_", 0) == 0 ? v->s.substr(8) : v->s;
  for (char& c : word) {
    c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  }
  return word;
}

}  // namespace

std::optional<std::string> attitude_plot_json(const schema::Value& attitude, std::int64_t offset_ns) {
  const auto stamp = stamp_ns(attitude);
  const auto time = stamp ? time_json(*stamp, offset_ns) : std::nullopt;
  if (!time) {
    return std::nullopt;
  }
  const schema::Value* filter = attitude.at("filter_id");
  return dump(
      {{"timestamp", *time},
       {"filter", filter != nullptr ? filter->s : std::string()},
       {"rpy_deg",
        {{"x", finite_or_null(number(attitude, "roll_rad") * kRadToDeg)},
         {"y", finite_or_null(number(attitude, "pitch_rad") * kRadToDeg)},
         {"z", finite_or_null(number(attitude, "yaw_rad") * kRadToDeg)}}},
       {"mag_disturbance_world_ut",
        {{"x", finite_or_null(number(attitude, "mag_disturbance_world_ut.x"))},
         {"y", finite_or_null(number(attitude, "mag_disturbance_world_ut.y"))},
         {"z", finite_or_null(number(attitude, "mag_disturbance_world_ut.z"))}}},
       {"mag_disturbance_norm_ut", finite_or_null(number(attitude, "mag_disturbance_norm_ut"))},
       {"mag_disturbance_angle_deg", finite_or_null(number(attitude, "mag_disturbance_angle_rad") * kRadToDeg)},
       {"mag_trusted", number(attitude, "mag_trusted") == 1.0 ? 1 : 0},
       {"heading_status", heading_word(attitude)},
       {"heading_verified", heading_word(attitude) == "verified" ? 1 : 0},
       {"yaw_sigma_deg", finite_or_null(std::sqrt(number(attitude, "attitude_covariance.8")) * kRadToDeg)}});
}

}  // namespace poise::foxglove
