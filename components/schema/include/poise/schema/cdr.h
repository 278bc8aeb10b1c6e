// CDR payload decoding against a TypeTable: serialized DDS samples -> a dynamic Value -> JSON or
// readable text. Pure C++17 (no Fast DDS).
//
// Wire format: XCDR1 plain CDR of final structs, as Fast DDS 2.9 / fastddsgen 2.3 write it. The
// payload starts with the 4-byte encapsulation header (00 01 00 00 = CDR little endian, 00 00 00 00
// = CDR big endian); primitives are aligned to their size (8 at most) relative to the first byte
// after that header. Every read is bounds-checked: a truncated or malformed payload is a
// DecodeError naming the field and byte offset, never a crash or an out-of-bounds read.
#pragma once

#include "poise/schema/idl_schema.h"

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace poise::schema {

/// A payload that does not match its type (truncated, bad encapsulation, bound exceeded, ...).
class DecodeError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A decoded sample: a tree of structs, lists (arrays and sequences) and scalars.
struct Value {
  enum class Kind : std::uint8_t { kBool, kInt, kUInt, kFloat, kString, kEnum, kStruct, kList };
  Kind kind = Kind::kInt;
  bool b = false;       // kBool
  std::int64_t i = 0;   // kInt (also char / int8 .. int64)
  std::uint64_t u = 0;  // kUInt (octet, uint8 .. uint64), kEnum (ordinal)
  double d = 0.0;       // kFloat (float or double)
  std::string s;        // kString; kEnum: enumerator name
  std::vector<std::pair<std::string, Value>> fields;  // kStruct, in declaration order
  std::vector<Value> items;                           // kList

  /// Member by name (kStruct) or nullptr.
  [[nodiscard]] const Value* field(const std::string& name) const;
  /// Member by dotted path ("header.stamp_ns", "detections.0.id") or nullptr.
  [[nodiscard]] const Value* at(const std::string& dotted_path) const;
};

/// Decodes `size` bytes (encapsulation header included) as the struct `type_name`.
/// Up to 3 trailing padding bytes are accepted; more is a DecodeError (wrong type?).
Value decode(const TypeTable& table, const std::string& type_name, const std::uint8_t* data,
             std::size_t size);
inline Value decode(const TypeTable& table, const std::string& type_name,
                    const std::vector<std::uint8_t>& payload) {
  return decode(table, type_name, payload.data(), payload.size());
}

/// Why `size` bytes are not a valid `type_name` payload (the DecodeError text), or nullopt when
/// they decode. The one check of untrusted payloads in the tools (record, echo, topics, replay,
/// process); nullopt as well when the table does not know the type (nothing to check against).
std::optional<std::string> payload_problem(const TypeTable& table, const std::string& type_name,
                                           const std::uint8_t* data, std::size_t size);

/// Compact single-line JSON (written by nlohmann-json, the project's one JSON writer). Structs are
/// objects (members in declaration order), arrays and
/// sequences are arrays, enums are their enumerator name as a string, booleans true/false, 64-bit
/// integers exact, doubles with round-trip precision; NaN and infinities (not representable in
/// JSON) are the strings "NaN", "Infinity", "-Infinity"; invalid UTF-8 becomes U+FFFD.
std::string to_json(const Value& value);

/// Readable multi-line text (YAML-like): `name: value` per line, nested structs indented two
/// spaces, lists of numbers inline `[1, 2, 3]`, lists of structs as `- ` items.
std::string to_text(const Value& value);

/// Big-endian CDR serialization of the @key members of `value` (a decoded `type_name`), as
/// fastddsgen's serializeKey() writes it: the input of the instance-handle computation. A @key
/// member of struct type contributes its own @key members, or all members if it has none.
std::vector<std::uint8_t> serialize_key_be(const TypeTable& table, const std::string& type_name,
                                           const Value& value);

/// header.stamp_ns of a poise sample: the int64 at payload bytes 4-11 (the first field of the
/// first member), read with the payload's endianness. nullopt if the payload is shorter than 12
/// bytes or its encapsulation is not CDR_LE / CDR_BE. Needs no type table (poise's IDL convention:
/// every topic type starts with `Header header;` whose first field is `int64 stamp_ns`).
std::optional<std::int64_t> read_header_stamp_ns(const std::uint8_t* data, std::size_t size);

/// True when `type_name` follows that convention (first member a struct whose first member is
/// int64 stamp_ns), so read_header_stamp_ns() is meaningful for it.
bool has_header_stamp(const TypeTable& table, const std::string& type_name);

/// header.stamp of a ROS 2 message (std_msgs/Header first: int32 sec, uint32 nanosec at payload
/// bytes 4-11) in ns; nullopt as read_header_stamp_ns(), and when sec < 0 or nanosec >= 1e9.
std::optional<std::int64_t> read_ros_header_stamp_ns(const std::uint8_t* data, std::size_t size);
/// True when the first member of `type_name` is a std_msgs::msg::dds_::Header_ (idl/ros2).
bool has_ros_header_stamp(const TypeTable& table, const std::string& type_name);

}  // namespace poise::schema
