#include "poise/schema/raw_type.h"

#include "poise/dds/participant.h"
#include "poise/schema/cdr.h"

#include <fastrtps/utils/md5.h>

#include <algorithm>
#include <cstring>

namespace poise::dds {

namespace rtps = eprosima::fastrtps::rtps;

RawPubSubType::RawPubSubType(const std::string& type_name, const schema::TypeTable* table,
                             bool keyed, std::uint32_t max_size)
    : table_(table) {
  setName(type_name.c_str());
  auto_fill_type_object(false);
  auto_fill_type_information(false);
  schema_ = table_ != nullptr ? table_->find_struct(type_name) : nullptr;
  if (schema_ != nullptr) {
    std::size_t size = table_->max_serialized_size(schema_->name);
    size += (4 - size % 4) % 4;  // possible submessage alignment, as the generated code adds
    m_typeSize = static_cast<std::uint32_t>(size + 4);  // + encapsulation
    m_isGetKeyDefined = schema_->has_key();
    key_max_size_ = table_->key_max_serialized_size(schema_->name);
  } else {
    m_typeSize = std::max<std::uint32_t>(max_size, 8);
    m_isGetKeyDefined = keyed;
  }
}

bool RawPubSubType::serialize(void* data, rtps::SerializedPayload_t* payload) {
  const auto* sample = static_cast<const RawSample*>(data);
  const std::size_t n = sample->data.size();
  if (n < 4 || n > payload->max_size) {
    return false;  // no encapsulation header, or larger than the payload Fast DDS reserved
  }
  std::memcpy(payload->data, sample->data.data(), n);
  payload->length = static_cast<std::uint32_t>(n);
  payload->encapsulation = sample->data[1] == 0 ? CDR_BE : CDR_LE;
  return true;
}

bool RawPubSubType::deserialize(rtps::SerializedPayload_t* payload, void* data) {
  auto* sample = static_cast<RawSample*>(data);
  sample->data.assign(payload->data, payload->data + payload->length);
  return true;
}

std::function<std::uint32_t()> RawPubSubType::getSerializedSizeProvider(void* data) {
  return [data]() { return static_cast<std::uint32_t>(static_cast<RawSample*>(data)->data.size()); };
}

void* RawPubSubType::createData() { return new RawSample(); }

void RawPubSubType::deleteData(void* data) { delete static_cast<RawSample*>(data); }

rtps::InstanceHandle_t RawPubSubType::undecodable_instance() {
  return poise::dds::undecodable_instance();
}

bool RawPubSubType::getKey(void* data, rtps::InstanceHandle_t* handle, bool force_md5) {
  if (!m_isGetKeyDefined) {
    return false;
  }
  // Never fail on a keyed type: Fast DDS 2.9 stores a fully received change whose key it cannot
  // compute in the reader history anyway, without an instance, and later aborts on it
  // (DataReaderHistory: `vit != instances_.end()`). Every payload without a computable key goes
  // to the one undecodable instance; the application sees it and rejects it (counted).
  if (schema_ == nullptr) {
    *handle = undecodable_instance();
    return true;
  }
  const auto* sample = static_cast<const RawSample*>(data);
  std::vector<std::uint8_t> key;
  try {
    key = schema::serialize_key_be(*table_, schema_->name,
                                     schema::decode(*table_, schema_->name, sample->data));
  } catch (const std::exception&) {
    *handle = undecodable_instance();  // a payload that does not decode has no key
    return true;
  }
  if (force_md5 || key_max_size_ > 16) {
    ::MD5 md5;  // Fast DDS 2.9 declares it in the global namespace
    md5.init();
    md5.update(key.data(), static_cast<unsigned int>(key.size()));
    md5.finalize();
    std::memcpy(handle->value, md5.digest, 16);
  } else {
    std::memset(handle->value, 0, 16);
    std::memcpy(handle->value, key.data(), std::min<std::size_t>(key.size(), 16));
  }
  return true;
}

}  // namespace poise::dds
