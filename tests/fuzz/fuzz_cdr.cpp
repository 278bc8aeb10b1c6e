// Fuzz target for the CDR decoder (issue 19): the schema-driven decoding of raw payloads that
// `poise echo`, `topics`, `record`, `replay` and `process` apply to bytes from the network or a
// file. Input: a scoped type name, a NUL, then the payload (encapsulation header included), e.g.
// "poise::msg::ImuSample\0\x00\x01\x00\x00...". An unknown name is decoded as the first builtin
// type so that every input exercises the decoder.
// Invariant: decode() returns a value or throws DecodeError with a message (any other exception,
// a crash, UB or an out-of-bounds read is a finding); payload_problem() agrees with decode(); a
// decoded value converts to JSON and text and yields its key; the header stamp readers never read
// past the payload.
#include "poise/schema/cdr.h"
#include "poise/schema/idl_schema.h"

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace poise::schema;
  const TypeTable& table = TypeTable::builtin();
  const void* nul = std::memchr(data, 0, size);
  const size_t name_len = nul != nullptr ? static_cast<size_t>(static_cast<const uint8_t*>(nul) - data) : 0;
  std::string type(reinterpret_cast<const char*>(data), name_len);
  const uint8_t* payload = nul != nullptr ? data + name_len + 1 : data;
  const size_t n = nul != nullptr ? size - name_len - 1 : size;
  if (table.find_struct(type) == nullptr) type = table.struct_names().front();
  // A private copy: an overread of the exact payload is then visible to ASan.
  const std::vector<uint8_t> bytes(payload, payload + n);

  bool decoded = false;
  try {
    const Value v = decode(table, type, bytes.data(), bytes.size());
    decoded = true;
    (void)to_json(v);
    (void)to_text(v);
    if (table.get_struct(type).has_key()) (void)serialize_key_be(table, type, v);
  } catch (const DecodeError& e) {
    if (e.what()[0] == '\0') std::abort();  // a rejection says why
  }
  const std::optional<std::string> problem = payload_problem(table, type, bytes.data(), bytes.size());
  if (problem.has_value() == decoded) std::abort();  // the tools' check disagrees with decode()
  (void)read_header_stamp_ns(bytes.data(), bytes.size());
  (void)read_ros_header_stamp_ns(bytes.data(), bytes.size());
  (void)has_header_stamp(table, type);
  (void)has_ros_header_stamp(table, type);
  return 0;
}
