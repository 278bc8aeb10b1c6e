// IDL schema layer: a type table parsed from the IDL subset poise's topic types use, and the
// self-contained `omgidl` schema text an MCAP recording stores per type.
//
// Supported IDL (anything else is a SchemaError naming file and line):
//  - `module m { ... };` (nested, reopenable), `struct S { members };`, `enum E { A, B };`
//  - `const <integer type> NAME = <integer literal or const name>;` (other const types are parsed
//    and kept as text but cannot be used as bounds)
//  - members `T name;`, arrays `T name[3][4];`, `sequence<T>` / `sequence<T, N>`,
//    `string` / `string<N>`, primitives (boolean, octet, char, int8..uint64, short/long/long long
//    and their unsigned forms, float, double)
//  - annotations `@key` / `@key(TRUE)` on members (others, e.g. @default, are accepted and ignored)
//  - `#include "file.idl"` of sibling files (resolved by file name); other preprocessor lines
//    (#pragma, include guards) are ignored; // and /* */ comments.
// Types must be declared before use (as IDL requires), which makes declaration order a valid
// dependency order. Pure C++17: no Fast DDS.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace poise::schema {

/// A malformed or unsupported IDL text, an unknown type, or an unreadable IDL directory.
class SchemaError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class PrimitiveKind : std::uint8_t {
  kBool, kOctet, kChar, kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kInt64, kUInt64,
  kFloat, kDouble
};

/// Wire size in bytes of a primitive (CDR: also its alignment).
std::size_t primitive_size(PrimitiveKind kind);
/// IDL spelling ("int64", "boolean", ...).
const char* primitive_name(PrimitiveKind kind);

/// The type of a member or of a sequence / array element.
struct TypeSpec {
  enum class Kind : std::uint8_t { kPrimitive, kString, kStruct, kEnum, kSequence, kArray };
  Kind kind = Kind::kPrimitive;
  PrimitiveKind primitive = PrimitiveKind::kInt32;  // kPrimitive
  std::uint32_t bound = 0;  // kString / kSequence: bound (0 = unbounded); kArray: length (> 0)
  std::string name;         // kStruct / kEnum: scoped name ("poise::msg::Header")
  std::shared_ptr<const TypeSpec> element;  // kSequence / kArray: element type
};

struct Member {
  std::string name;
  TypeSpec type;
  bool key = false;  // @key
};

struct StructDef {
  std::string name;  // scoped, "poise::msg::ImuSample"
  std::vector<Member> members;
  std::string file;  // IDL file it came from (for messages)
  [[nodiscard]] bool has_key() const;
};

struct EnumDef {
  std::string name;  // scoped
  std::vector<std::string> enumerators;  // value = index
};

struct ConstDef {
  std::string name;   // scoped
  std::string type;   // IDL spelling of the type
  std::string value;  // literal text as written
};

/// All types from a set of IDL files. Immutable after loading; cheap to share by const reference.
class TypeTable {
 public:
  /// poise's own topic types and the ROS 2 types: from_directory($POISE_IDL_DIR) when that variable
  /// is set, else the IDL texts embedded into the library at build time (the installed binary
  /// needs no source tree).
  static const TypeTable& builtin();
  /// Every *.idl file in `dir` and in `dir`/ros2 when that exists (idl/ and idl/ros2/).
  static TypeTable from_directory(const std::string& dir);
  /// IDL texts by file name (e.g. {"common.idl", "..."}); #include resolves among these names.
  static TypeTable from_sources(const std::map<std::string, std::string>& files);

  /// Null when `scoped_name` ("poise::msg::ImuSample", leading "::" allowed) is not a struct.
  [[nodiscard]] const StructDef* find_struct(std::string_view scoped_name) const;
  [[nodiscard]] const EnumDef* find_enum(std::string_view scoped_name) const;
  /// Like find_struct, but throws SchemaError listing the known types.
  [[nodiscard]] const StructDef& get_struct(std::string_view scoped_name) const;
  /// Scoped names of every struct, in declaration (dependency) order.
  [[nodiscard]] std::vector<std::string> struct_names() const;
  [[nodiscard]] const std::vector<ConstDef>& constants() const { return constants_; }

  /// One self-contained IDL text holding `scoped_name` and every type it depends on, in
  /// dependency order, wrapped in their modules, with bounds resolved to numbers and no
  /// preprocessor directives: the MCAP `omgidl` schema (what Foxglove parses).
  [[nodiscard]] std::string flatten(std::string_view scoped_name) const;

  /// Largest XCDR1 serialized size of the struct without the 4-byte encapsulation, computed as
  /// fastddsgen 2.3 does (an unbounded string counts 255 characters, an unbounded sequence 100
  /// elements).
  [[nodiscard]] std::size_t max_serialized_size(std::string_view scoped_name) const;
  /// Largest size of the big-endian key serialization (0 when the struct has no @key member).
  [[nodiscard]] std::size_t key_max_serialized_size(std::string_view scoped_name) const;

  // Building (used by the parser).
  void add_struct(StructDef def);
  void add_enum(EnumDef def);
  void add_constant(ConstDef def, std::optional<std::int64_t> integer_value);
  [[nodiscard]] std::optional<std::int64_t> integer_constant(std::string_view scoped) const;
  [[nodiscard]] bool has_type(std::string_view scoped) const;

 private:
  std::size_t max_size(const TypeSpec& t, std::size_t offset) const;
  std::size_t key_max_size(const StructDef& s, std::size_t offset) const;

  struct Declared {
    bool is_struct;
    std::size_t index;
  };
  std::vector<Declared> order_;  // declaration order of structs and enums
  std::vector<StructDef> structs_;
  std::vector<EnumDef> enums_;
  std::vector<ConstDef> constants_;
  std::map<std::string, std::int64_t, std::less<>> integer_constants_;
  std::map<std::string, std::size_t, std::less<>> struct_index_;
  std::map<std::string, std::size_t, std::less<>> enum_index_;
};

/// The IDL texts embedded at build time, by file name.
const std::map<std::string, std::string>& embedded_idl_sources();

}  // namespace poise::schema
