// A Fast DDS type that carries the serialized payload verbatim (encapsulation header included)
// under another type's name: the recorder receives without deserializing and the replayer
// publishes byte for byte. For keyed types the instance key is computed by the generated type.
#pragma once

#include <fastdds/dds/topic/TopicDataType.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace poise::record {

/// One sample of a RawPubSubType: the full serialized payload.
struct RawSample {
  std::vector<uint8_t> bytes;
};

class RawPubSubType : public eprosima::fastdds::dds::TopicDataType {
 public:
  /// TYPE_NAME as on the wire; GENERATED (may be null) is the real type, used for the key and the
  /// maximum size. Without it the type is unkeyed with a 64 KiB size hint.
  RawPubSubType(const std::string& type_name,
                std::unique_ptr<eprosima::fastdds::dds::TopicDataType> generated);

  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override;
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override;
  std::function<uint32_t()> getSerializedSizeProvider(void* data) override;
  void* createData() override;
  void deleteData(void* data) override;
  bool getKey(void* data, eprosima::fastrtps::rtps::InstanceHandle_t* handle,
              bool force_md5) override;

 private:
  std::unique_ptr<eprosima::fastdds::dds::TopicDataType> generated_;
};

/// The generated type support of a poise message type ("poise::msg::ImuSample"), or null.
std::unique_ptr<eprosima::fastdds::dds::TopicDataType> make_generated_type(
    const std::string& type_name);

/// Names of every poise topic type make_generated_type() knows.
std::vector<std::string> known_type_names();

/// The sample stamp (Header.stamp_ns) of a poise payload: every poise type starts with Header, so
/// stamp_ns is the int64 right after the 4-byte encapsulation header (XCDR1, either endianness).
/// Returns false if the payload is too short or not CDR.
bool header_stamp_ns(const uint8_t* payload, size_t size, int64_t* stamp_ns);

}  // namespace poise::record
