#include "poise/record/raw_type.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <fastdds/rtps/common/SerializedPayload.h>

#include <cstring>
#include <functional>
#include <map>

namespace poise::record {

namespace fdds = eprosima::fastdds::dds;
using eprosima::fastrtps::rtps::InstanceHandle_t;
using eprosima::fastrtps::rtps::SerializedPayload_t;

namespace {
constexpr uint32_t kUnknownTypeSize = 64 * 1024;

const std::map<std::string, std::function<fdds::TopicDataType*()>>& registry() {
  static const std::map<std::string, std::function<fdds::TopicDataType*()>> types{
      {"poise::msg::ImuSample", [] { return new msg::ImuSamplePubSubType(); }},
      {"poise::msg::VehicleInput", [] { return new msg::VehicleInputPubSubType(); }},
      {"poise::msg::TagDetections", [] { return new msg::TagDetectionsPubSubType(); }},
      {"poise::msg::VisionPose", [] { return new msg::VisionPosePubSubType(); }},
      {"poise::msg::AttitudeEstimate", [] { return new msg::AttitudeEstimatePubSubType(); }},
      {"poise::msg::PoseEstimate", [] { return new msg::PoseEstimatePubSubType(); }},
      {"poise::msg::AltitudeEstimate", [] { return new msg::AltitudeEstimatePubSubType(); }},
      {"poise::msg::FilterDiagnostics", [] { return new msg::FilterDiagnosticsPubSubType(); }},
  };
  return types;
}

uint16_t encapsulation_of(const std::vector<uint8_t>& bytes) {
  // Byte 1 of the representation identifier: 0x00 = CDR big endian, 0x01 = CDR little endian.
  return bytes.size() >= 2 && bytes[1] == 0 ? CDR_BE : CDR_LE;
}
}  // namespace

RawPubSubType::RawPubSubType(const std::string& type_name,
                             std::unique_ptr<fdds::TopicDataType> generated)
    : generated_(std::move(generated)) {
  setName(type_name.c_str());
  if (generated_) {
    m_typeSize = generated_->m_typeSize;
    m_isGetKeyDefined = generated_->m_isGetKeyDefined;
  } else {
    m_typeSize = kUnknownTypeSize;
    m_isGetKeyDefined = false;
  }
}

bool RawPubSubType::serialize(void* data, SerializedPayload_t* payload) {
  const auto* sample = static_cast<const RawSample*>(data);
  if (sample->bytes.size() > payload->max_size) {
    return false;  // larger than the type's maximum size: Fast DDS reports the write as failed
  }
  std::memcpy(payload->data, sample->bytes.data(), sample->bytes.size());
  payload->length = static_cast<uint32_t>(sample->bytes.size());
  payload->encapsulation = encapsulation_of(sample->bytes);
  return true;
}

bool RawPubSubType::deserialize(SerializedPayload_t* payload, void* data) {
  auto* sample = static_cast<RawSample*>(data);
  sample->bytes.assign(payload->data, payload->data + payload->length);
  return true;
}

std::function<uint32_t()> RawPubSubType::getSerializedSizeProvider(void* data) {
  const auto* sample = static_cast<const RawSample*>(data);
  return [sample] { return static_cast<uint32_t>(sample->bytes.size()); };
}

void* RawPubSubType::createData() { return new RawSample(); }

void RawPubSubType::deleteData(void* data) { delete static_cast<RawSample*>(data); }

bool RawPubSubType::getKey(void* data, InstanceHandle_t* handle, bool force_md5) {
  if (!generated_ || !m_isGetKeyDefined) {
    return false;
  }
  const auto* sample = static_cast<const RawSample*>(data);
  SerializedPayload_t payload(static_cast<uint32_t>(sample->bytes.size()));
  std::memcpy(payload.data, sample->bytes.data(), sample->bytes.size());
  payload.length = static_cast<uint32_t>(sample->bytes.size());
  payload.encapsulation = encapsulation_of(sample->bytes);
  void* object = generated_->createData();
  const bool ok = generated_->deserialize(&payload, object) &&
                  generated_->getKey(object, handle, force_md5);
  generated_->deleteData(object);
  return ok;
}

std::unique_ptr<fdds::TopicDataType> make_generated_type(const std::string& type_name) {
  const auto found = registry().find(type_name);
  if (found == registry().end()) {
    return nullptr;
  }
  return std::unique_ptr<fdds::TopicDataType>(found->second());
}

std::vector<std::string> known_type_names() {
  std::vector<std::string> out;
  for (const auto& entry : registry()) {
    out.push_back(entry.first);
  }
  return out;
}

bool header_stamp_ns(const uint8_t* payload, size_t size, int64_t* stamp_ns) {
  if (size < 12 || payload[0] != 0x00 || payload[1] > 0x01) {
    return false;
  }
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) {
    const uint8_t byte = payload[4 + i];
    if (payload[1] == 0x01) {
      v |= static_cast<uint64_t>(byte) << (8 * i);  // little endian
    } else {
      v = (v << 8) | byte;  // big endian
    }
  }
  *stamp_ns = static_cast<int64_t>(v);
  return true;
}

}  // namespace poise::record
