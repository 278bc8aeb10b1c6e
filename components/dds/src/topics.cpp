#include "poise/dds/topics.h"

#include <stdexcept>

namespace poise::dds {

const std::string& checked_sensor_id(const std::string& name, const std::string& where) {
  if (name.empty()) {
    throw std::invalid_argument(where + ": the instance name (sensor_id) must not be empty");
  }
  if (name.size() > kMaxSensorIdLength) {
    throw std::invalid_argument(where + ": instance name '" + name + "' has " + std::to_string(name.size()) +
                                " characters; a sensor_id (the DDS key) holds at most " +
                                std::to_string(kMaxSensorIdLength) + " and is never cut: choose a shorter name");
  }
  return name;
}

const char* profile_name(QosKind kind) {
  switch (kind) {
    case QosKind::kSensor:
      return "sensor";
    case QosKind::kEstimate:
      return "estimate";
    case QosKind::kStatic:
      return "static";
  }
  return "estimate";
}

QosKind default_qos_for_topic(const std::string& topic, const TopicNames& names) {
  if (topic == names.imu || topic == names.tag_detections || topic == names.vehicle_input) {
    return QosKind::kSensor;
  }
  if (topic == names.imu_info) {
    return QosKind::kStatic;
  }
  return QosKind::kEstimate;
}

}  // namespace poise::dds
