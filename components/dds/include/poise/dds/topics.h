// Topic names and the QoS profile each kind of topic uses: defined once, here.
#pragma once

#include <cstddef>
#include <string>

namespace poise::dds {

/// Names of the topics poise publishes. Defaults below; every component takes overrides from its
/// host file (`topics:` map) or command line.
struct TopicNames {
  std::string imu = "imu";                        ///< msg::ImuSample
  std::string imu_info = "imu_info";              ///< msg::ImuSensorInfo (the IMU's delay)
  std::string tag_detections = "tag_detections";  ///< msg::TagDetections
  std::string vision_pose = "vision_pose";        ///< msg::VisionPose
  std::string attitude_prefix = "attitude/";      ///< msg::AttitudeEstimate, + filter id
  std::string pose_prefix = "pose/";              ///< msg::PoseEstimate, + filter id
  std::string altitude = "altitude";              ///< msg::AltitudeEstimate
  std::string vehicle_input = "vehicle_input";    ///< msg::VehicleInput
  std::string diagnostics = "diagnostics";        ///< msg::FilterDiagnostics

  [[nodiscard]] std::string attitude(const std::string& filter_id) const {
    return attitude_prefix + filter_id;
  }
  [[nodiscard]] std::string pose(const std::string& filter_id) const {
    return pose_prefix + filter_id;
  }
};

/// The IDL bound of `sensor_id` (`@key string<64>`): a longer name would be cut by the generated
/// types, so two instances could publish under one key.
inline constexpr std::size_t kMaxSensorIdLength = 64;

/// Returns `name` when it can be a sensor_id (1 to kMaxSensorIdLength characters); otherwise
/// throws std::invalid_argument "<where>: instance name '<name>' ..." (refused, never cut).
const std::string& checked_sensor_id(const std::string& name, const std::string& where);

/// The endpoint QoS profiles of config/qos/poise_profiles.xml.
enum class QosKind {
  kSensor,    ///< best-effort keep-last: high-rate sensor streams
  kEstimate,  ///< reliable keep-last: estimates, diagnostics
  kStatic,    ///< reliable transient-local keep-last 1: static data
};

/// XML profile name of a QoS kind ("sensor", "estimate", "static").
const char* profile_name(QosKind kind);

/// The QoS kind poise uses for a topic name under the default names: sensor streams for `imu`,
/// `tag_detections`, `vehicle_input`; static for `imu_info`; estimate for everything else.
QosKind default_qos_for_topic(const std::string& topic, const TopicNames& names = TopicNames{});

/// Fully qualified DDS type names of the poise messages (as registered by the generated types).
namespace type_names {
inline constexpr const char* kImuSample = "poise::msg::ImuSample";
inline constexpr const char* kImuSensorInfo = "poise::msg::ImuSensorInfo";
inline constexpr const char* kVehicleInput = "poise::msg::VehicleInput";
inline constexpr const char* kTagDetections = "poise::msg::TagDetections";
inline constexpr const char* kVisionPose = "poise::msg::VisionPose";
inline constexpr const char* kAttitudeEstimate = "poise::msg::AttitudeEstimate";
inline constexpr const char* kPoseEstimate = "poise::msg::PoseEstimate";
inline constexpr const char* kAltitudeEstimate = "poise::msg::AltitudeEstimate";
inline constexpr const char* kFilterDiagnostics = "poise::msg::FilterDiagnostics";
}  // namespace type_names

}  // namespace poise::dds
