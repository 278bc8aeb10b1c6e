// Fuzz target for the recorder's raw payload path (issue 19): the serialized payload a DDS reader
// hands to `poise record` (and `echo`/`topics`), through the same calls as the recorder's
// listener: RawPubSubType::deserialize() and getKey() (the instance handle Fast DDS asks for on
// every received change), payload_problem() (the one check that rejects and counts), the header
// stamp, then McapWriter::write() into an in-memory MCAP, finalised and read back.
// Input: a scoped type name, a NUL, then the payload (as fuzz_cdr); an unknown name is a type
// without a schema (recorded unchecked, as the recorder does for types this build does not know).
// Invariant: deserialize() accepts any length and copies it verbatim; getKey() of a keyed type
// never fails and gives the undecodable instance to every payload that does not decode;
// serialize() refuses what is not a payload or does not fit; an accepted payload comes back from
// the finalised file byte for byte, in a complete file. Nothing crashes.
#include "poise/schema/cdr.h"
#include "poise/schema/idl_schema.h"
#include "poise/schema/raw_type.h"
#include "poise/record/io.h"
#include "poise/record/mcap.h"

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace {

namespace rtps = eprosima::fastrtps::rtps;

void check(bool ok) {
  if (!ok) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace poise;
  const schema::TypeTable& table = schema::TypeTable::builtin();
  const void* nul = std::memchr(data, 0, size);
  if (nul == nullptr) return 0;
  const size_t name_len = static_cast<size_t>(static_cast<const uint8_t*>(nul) - data);
  const std::string type(reinterpret_cast<const char*>(data), name_len);
  const std::vector<uint8_t> bytes(data + name_len + 1, data + size);

  // DDS side: what Fast DDS does with a received change.
  dds::RawPubSubType raw(type.empty() ? "x" : type, &table, /*keyed=*/(size & 1) != 0);
  rtps::SerializedPayload_t payload(static_cast<uint32_t>(bytes.size()));
  if (!bytes.empty()) std::memcpy(payload.data, bytes.data(), bytes.size());
  payload.length = static_cast<uint32_t>(bytes.size());
  dds::RawSample sample;
  check(raw.deserialize(&payload, &sample));
  check(sample.data == bytes);
  const std::optional<std::string> problem =
      schema::payload_problem(table, type, sample.data.data(), sample.data.size());
  if (raw.m_isGetKeyDefined) {
    rtps::InstanceHandle_t handle;
    check(raw.getKey(&sample, &handle, false));
    rtps::InstanceHandle_t md5;
    check(raw.getKey(&sample, &md5, true));
    if (problem || raw.schema() == nullptr) {
      check(handle == dds::RawPubSubType::undecodable_instance());
    }
  }
  {
    rtps::SerializedPayload_t out(raw.m_typeSize);
    const bool fits = bytes.size() >= 4 && bytes.size() <= out.max_size;
    check(raw.serialize(&sample, &out) == fits);
    if (fits) check(out.length == bytes.size() && std::memcmp(out.data, bytes.data(), bytes.size()) == 0);
    check(raw.getSerializedSizeProvider(&sample)() == bytes.size());
  }
  if (problem) {
    check(!problem->empty());  // counted and reported by the recorder; never written
    return 0;
  }

  // Recorder side: the header stamp as publish time, then the MCAP writer.
  std::optional<int64_t> stamp;
  if (schema::has_ros_header_stamp(table, type)) {
    stamp = schema::read_ros_header_stamp_ns(sample.data.data(), sample.data.size());
  } else if (schema::has_header_stamp(table, type)) {
    stamp = schema::read_header_stamp_ns(sample.data.data(), sample.data.size());
  }
  const uint64_t publish_ns = stamp.value_or(0) > 0 ? static_cast<uint64_t>(stamp.value_or(0)) : 0;
  std::vector<uint8_t> file;
  {
    record::WriterOptions options;
    options.clock = [] { return int64_t{0}; };
    record::McapWriter writer(std::make_unique<record::MemorySink>(file), options);
    uint16_t schema_id = 0;
    if (raw.schema() != nullptr) {
      const std::string idl = table.flatten(type);
      schema_id = writer.add_schema(type, "omgidl", std::vector<uint8_t>(idl.begin(), idl.end()));
    }
    const uint16_t channel = writer.add_channel(schema_id, "fuzz", "cdr", {{"dds_type", type}});
    writer.write(channel, 7, 1000, publish_ns,
                 sample.data.data(), sample.data.size());
    writer.close();
  }
  record::McapReader reader(std::make_unique<record::MemorySource>(file));
  check(reader.report().complete);
  auto cursor = reader.messages();
  const record::MessageView* m = cursor.next();
  check(m != nullptr && m->size == bytes.size());
  check(bytes.empty() || std::memcmp(m->data, bytes.data(), bytes.size()) == 0);
  check(cursor.next() == nullptr);
  return 0;
}
