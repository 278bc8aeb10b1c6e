// A Fast DDS TopicDataType whose samples are serialized payloads, verbatim.
//
// `poise echo`, `poise topics`, the MCAP recorder and the replayer subscribe / publish any topic
// with it without generated type support: serialize() and deserialize() copy the payload bytes,
// encapsulation header included. The DDS type name is whatever the peer uses, so a raw reader
// matches a typed writer (and a raw writer a typed reader) of the same name.
//
// Keys: a keyed writer and an unkeyed reader never match in Fast DDS (the topic kind is part of
// endpoint matching), so the raw type must declare a key exactly when the real type does. When the
// type is in the given TypeTable, the instance handle is computed from the payload as fastddsgen
// 2.3 does: the @key members serialized big-endian, MD5 of them when the key's maximum serialized
// size exceeds 16 bytes (or when forced), else the bytes zero-padded to 16. Identical handles to
// the generated type support (tested). Without a schema the type can still be declared keyed
// (`keyed`): a raw reader then relies on the key hash Fast DDS writers send inline.
//
// Untrusted bytes: getKey() of a keyed raw type never fails. A payload that does not decode (or
// any payload of a keyed type without a schema) gets undecodable_instance(), one fixed handle, so
// a malformed sample from a stranger is handed to the application (which counts and rejects it)
// instead of reaching Fast DDS 2.9's reader history without an instance, where it aborts the
// process. deserialize() copies any length, 0 included; serialize() refuses what is not a payload.
#pragma once

#include "poise/schema/idl_schema.h"

#include <fastdds/dds/topic/TopicDataType.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace poise::dds {

/// One sample of a raw topic: the complete serialized payload (4-byte encapsulation included).
struct RawSample {
  std::vector<std::uint8_t> data;
};

class RawPubSubType : public eprosima::fastdds::dds::TopicDataType {
 public:
  /// Payload size assumed for types without a schema when the caller has no better figure.
  static constexpr std::uint32_t kDefaultMaxSize = 64 * 1024;

  /// A raw type for `type_name`. If `table` (not owned; must outlive this object) holds the type,
  /// its maximum size and key come from the schema; otherwise the type is keyed iff `keyed` and
  /// payloads up to `max_size` bytes are preallocated (larger ones are reallocated).
  RawPubSubType(const std::string& type_name, const schema::TypeTable* table, bool keyed = false,
                std::uint32_t max_size = kDefaultMaxSize);

  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override;
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override;
  std::function<std::uint32_t()> getSerializedSizeProvider(void* data) override;
  void* createData() override;
  void deleteData(void* data) override;
  bool getKey(void* data, eprosima::fastrtps::rtps::InstanceHandle_t* handle,
              bool force_md5 = false) override;

  /// The instance of every payload whose key cannot be computed (16 bytes 0xFF).
  static eprosima::fastrtps::rtps::InstanceHandle_t undecodable_instance();

  /// True when instance handles are computed from the schema.
  [[nodiscard]] bool computes_keys() const { return schema_ != nullptr && m_isGetKeyDefined; }
  /// The schema used (null when the type is unknown to the table).
  [[nodiscard]] const schema::StructDef* schema() const { return schema_; }

 private:
  const schema::TypeTable* table_ = nullptr;
  const schema::StructDef* schema_ = nullptr;
  std::size_t key_max_size_ = 0;
};

}  // namespace poise::dds
