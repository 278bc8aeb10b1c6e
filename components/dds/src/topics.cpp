#include "poise/dds/topics.h"

namespace poise::dds {

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
  return QosKind::kEstimate;
}

}  // namespace poise::dds
