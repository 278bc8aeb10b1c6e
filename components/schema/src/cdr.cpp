#include "poise/schema/cdr.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <sstream>

namespace poise::schema {

const Value* Value::field(const std::string& name) const {
  for (const auto& [n, v] : fields) {
    if (n == name) {
      return &v;
    }
  }
  return nullptr;
}

const Value* Value::at(const std::string& dotted_path) const {
  const Value* v = this;
  std::size_t start = 0;
  while (v != nullptr && start <= dotted_path.size()) {
    const std::size_t dot = dotted_path.find('.', start);
    const std::string part = dotted_path.substr(start, dot == std::string::npos ? dot : dot - start);
    if (v->kind == Kind::kList) {
      char* end = nullptr;
      const unsigned long index = std::strtoul(part.c_str(), &end, 10);
      v = (part.empty() || *end != '\0' || index >= v->items.size()) ? nullptr : &v->items[index];
    } else {
      v = v->field(part);
    }
    if (dot == std::string::npos) {
      break;
    }
    start = dot + 1;
  }
  return v;
}

namespace {

constexpr std::size_t kEncapsulationSize = 4;
constexpr std::size_t kMaxTrailingPadding = 3;

class Reader {
 public:
  Reader(const TypeTable& table, const std::uint8_t* data, std::size_t size)
      : table_(table), data_(data), size_(size) {
    if (size < kEncapsulationSize) {
      throw DecodeError("payload of " + std::to_string(size) +
                        " bytes is shorter than the 4-byte encapsulation header");
    }
    if (data[0] != 0 || (data[1] != 0 && data[1] != 1)) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "%02x%02x", data[0], data[1]);
      throw DecodeError(std::string("unsupported encapsulation 0x") + hex +
                        " (only XCDR1 plain CDR 0x0000 / 0x0001 is supported)");
    }
    little_ = data[1] == 1;
    pos_ = kEncapsulationSize;
  }

  Value read_struct(const StructDef& s, std::string& path) {
    Value v;
    v.kind = Value::Kind::kStruct;
    v.fields.reserve(s.members.size());
    for (const auto& m : s.members) {
      const std::size_t mark = path.size();
      path += (path.empty() ? "" : ".") + m.name;
      v.fields.emplace_back(m.name, read(m.type, path));
      path.resize(mark);
    }
    return v;
  }

  void finish(const std::string& type_name) const {
    const std::size_t rest = size_ - pos_;
    if (rest > kMaxTrailingPadding) {
      throw DecodeError(std::to_string(rest) + " unexpected bytes after the end of " + type_name +
                        " at byte " + std::to_string(pos_) + " (payload of another type?)");
    }
  }

 private:
  [[noreturn]] void truncated(const std::string& path, std::size_t need) const {
    throw DecodeError("payload truncated: " + path + " needs " + std::to_string(need) +
                      " bytes at byte " + std::to_string(pos_) + " but the payload has " +
                      std::to_string(size_) + " bytes");
  }

  void align(std::size_t n, const std::string& path) {
    const std::size_t rel = pos_ - kEncapsulationSize;
    const std::size_t pad = (n - rel % n) % n;
    if (pad > size_ - pos_) {
      truncated(path, pad);
    }
    pos_ += pad;
  }

  std::uint64_t read_unsigned(std::size_t n, const std::string& path) {
    align(n, path);
    if (n > size_ - pos_) {
      truncated(path, n);
    }
    std::uint64_t v = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t byte = little_ ? k : n - 1 - k;
      v |= static_cast<std::uint64_t>(data_[pos_ + k]) << (8 * byte);
    }
    pos_ += n;
    return v;
  }

  static std::int64_t sign_extend(std::uint64_t v, std::size_t n) {
    if (n == 8) {
      std::int64_t out = 0;
      std::memcpy(&out, &v, sizeof out);
      return out;
    }
    const std::uint64_t sign = std::uint64_t{1} << (8 * n - 1);
    const std::uint64_t mask = (std::uint64_t{1} << (8 * n)) - 1;
    v &= mask;
    return (v & sign) != 0 ? -static_cast<std::int64_t>((~v & mask) + 1) : static_cast<std::int64_t>(v);
  }

  Value read_primitive(PrimitiveKind k, const std::string& path) {
    Value v;
    const std::size_t n = primitive_size(k);
    const std::uint64_t raw = read_unsigned(n, path);
    switch (k) {
      case PrimitiveKind::kBool:
        if (raw > 1) {
          throw DecodeError("boolean " + path + " has the invalid value " + std::to_string(raw) +
                            " at byte " + std::to_string(pos_ - 1));
        }
        v.kind = Value::Kind::kBool;
        v.b = raw == 1;
        break;
      case PrimitiveKind::kChar:
      case PrimitiveKind::kInt8:
      case PrimitiveKind::kInt16:
      case PrimitiveKind::kInt32:
      case PrimitiveKind::kInt64:
        v.kind = Value::Kind::kInt;
        v.i = sign_extend(raw, n);
        break;
      case PrimitiveKind::kOctet:
      case PrimitiveKind::kUInt8:
      case PrimitiveKind::kUInt16:
      case PrimitiveKind::kUInt32:
      case PrimitiveKind::kUInt64:
        v.kind = Value::Kind::kUInt;
        v.u = raw;
        break;
      case PrimitiveKind::kFloat: {
        const auto bits = static_cast<std::uint32_t>(raw);
        float f = 0.0F;
        std::memcpy(&f, &bits, sizeof f);
        v.kind = Value::Kind::kFloat;
        v.d = static_cast<double>(f);
        break;
      }
      case PrimitiveKind::kDouble: {
        double d = 0.0;
        std::memcpy(&d, &raw, sizeof d);
        v.kind = Value::Kind::kFloat;
        v.d = d;
        break;
      }
    }
    return v;
  }

  Value read(const TypeSpec& t, std::string& path) {
    switch (t.kind) {
      case TypeSpec::Kind::kPrimitive:
        return read_primitive(t.primitive, path);
      case TypeSpec::Kind::kEnum: {
        const EnumDef* e = table_.find_enum(t.name);
        const std::uint64_t ordinal = read_unsigned(4, path);
        if (e == nullptr || ordinal >= e->enumerators.size()) {
          throw DecodeError("enum " + path + " has the invalid value " + std::to_string(ordinal));
        }
        Value v;
        v.kind = Value::Kind::kEnum;
        v.u = ordinal;
        v.s = e->enumerators[ordinal];
        return v;
      }
      case TypeSpec::Kind::kString: {
        const std::uint64_t length = read_unsigned(4, path);  // characters + terminating NUL
        if (length > size_ - pos_) {
          throw DecodeError("payload truncated: string " + path + " of length " +
                            std::to_string(length) + " at byte " + std::to_string(pos_) +
                            " runs past the end of the " + std::to_string(size_) + "-byte payload");
        }
        Value v;
        v.kind = Value::Kind::kString;
        if (length == 0) {
          return v;  // some implementations write an empty string without its NUL
        }
        if (data_[pos_ + length - 1] != 0) {
          throw DecodeError("string " + path + " at byte " + std::to_string(pos_) +
                            " is not NUL-terminated");
        }
        if (t.bound != 0 && length - 1 > t.bound) {
          throw DecodeError("string " + path + " has " + std::to_string(length - 1) +
                            " characters, more than its bound " + std::to_string(t.bound));
        }
        v.s.assign(reinterpret_cast<const char*>(data_ + pos_), length - 1);
        pos_ += length;
        return v;
      }
      case TypeSpec::Kind::kSequence: {
        const std::uint64_t count = read_unsigned(4, path);
        if (t.bound != 0 && count > t.bound) {
          throw DecodeError("sequence " + path + " has " + std::to_string(count) +
                            " elements, more than its bound " + std::to_string(t.bound));
        }
        if (count > size_ - pos_) {  // every element takes at least one byte
          throw DecodeError("payload truncated: sequence " + path + " claims " +
                            std::to_string(count) + " elements but only " +
                            std::to_string(size_ - pos_) + " bytes remain");
        }
        return read_list(*t.element, count, path);
      }
      case TypeSpec::Kind::kArray:
        return read_list(*t.element, t.bound, path);
      case TypeSpec::Kind::kStruct:
        return read_struct(table_.get_struct(t.name), path);
    }
    throw DecodeError("internal: unknown type kind at " + path);
  }

  Value read_list(const TypeSpec& element, std::uint64_t count, std::string& path) {
    Value v;
    v.kind = Value::Kind::kList;
    v.items.reserve(count);
    for (std::uint64_t k = 0; k < count; ++k) {
      const std::size_t mark = path.size();
      path += "[" + std::to_string(k) + "]";
      v.items.push_back(read(element, path));
      path.resize(mark);
    }
    return v;
  }

  const TypeTable& table_;
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  bool little_ = true;
};

// ---------------------------------------------------------------------------------------------
// Output

// The one JSON writer is nlohmann-json. NaN and infinities (not representable in JSON) become the
// strings "NaN", "Infinity", "-Infinity"; invalid UTF-8 bytes in strings become U+FFFD.
nlohmann::ordered_json json_of(const Value& v) {
  switch (v.kind) {
    case Value::Kind::kBool: return v.b;
    case Value::Kind::kInt: return v.i;
    case Value::Kind::kUInt: return v.u;
    case Value::Kind::kFloat:
      if (std::isnan(v.d)) {
        return "NaN";
      }
      if (std::isinf(v.d)) {
        return v.d > 0 ? "Infinity" : "-Infinity";
      }
      return v.d;
    case Value::Kind::kString:
    case Value::Kind::kEnum: return v.s;
    case Value::Kind::kStruct: {
      nlohmann::ordered_json o = nlohmann::ordered_json::object();
      for (const auto& [name, field] : v.fields) {
        o[name] = json_of(field);
      }
      return o;
    }
    case Value::Kind::kList: {
      nlohmann::ordered_json a = nlohmann::ordered_json::array();
      for (const auto& item : v.items) {
        a.push_back(json_of(item));
      }
      return a;
    }
  }
  return nullptr;
}

void append_json(std::string& out, const Value& v) {
  out += json_of(v).dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
}

bool is_scalar(const Value& v) { return v.kind != Value::Kind::kStruct && v.kind != Value::Kind::kList; }

bool is_flat_list(const Value& v) {
  if (v.kind != Value::Kind::kList) {
    return false;
  }
  for (const auto& item : v.items) {
    if (!is_scalar(item)) {
      return false;
    }
  }
  return true;
}

void append_text_fields(std::string& out, const Value& v, std::size_t indent, bool first_inline);

// A value after "name:" (or after "- "): scalars and flat lists inline, the rest on new lines.
void append_text_value(std::string& out, const Value& v, std::size_t indent) {
  if (is_scalar(v) || is_flat_list(v)) {
    out += ' ';
    std::string json;
    append_json(json, v);
    if (v.kind == Value::Kind::kList) {  // readable spacing: [1, 2, 3]
      std::string spaced;
      bool in_string = false;
      for (std::size_t k = 0; k < json.size(); ++k) {
        const char c = json[k];
        if (c == '"' && (k == 0 || json[k - 1] != '\\')) {
          in_string = !in_string;
        }
        spaced += c;
        if (c == ',' && !in_string) {
          spaced += ' ';
        }
      }
      json = spaced;
    }
    out += json;
    out += '\n';
    return;
  }
  out += '\n';
  if (v.kind == Value::Kind::kStruct) {
    append_text_fields(out, v, indent, false);
    return;
  }
  for (const auto& item : v.items) {
    out.append(indent, ' ');
    out += '-';
    if (item.kind == Value::Kind::kStruct) {
      out += ' ';
      append_text_fields(out, item, indent + 2, true);
    } else {
      append_text_value(out, item, indent + 2);
    }
  }
}

void append_text_fields(std::string& out, const Value& v, std::size_t indent, bool first_inline) {
  bool first = true;
  for (const auto& [name, field] : v.fields) {
    if (!(first && first_inline)) {
      out.append(indent, ' ');
    }
    first = false;
    out += name;
    out += ':';
    append_text_value(out, field, indent + 2);
  }
}

// ---------------------------------------------------------------------------------------------
// Key serialization (big endian, aligned from the start of the key buffer)

class KeyWriter {
 public:
  explicit KeyWriter(const TypeTable& table) : table_(table) {}
  std::vector<std::uint8_t> bytes;

  void put_unsigned(std::uint64_t v, std::size_t n) {
    bytes.resize(bytes.size() + (n - bytes.size() % n) % n, 0);
    for (std::size_t k = 0; k < n; ++k) {
      bytes.push_back(static_cast<std::uint8_t>(v >> (8 * (n - 1 - k))));
    }
  }

  void write(const TypeSpec& t, const Value& v) {
    switch (t.kind) {
      case TypeSpec::Kind::kPrimitive: {
        const std::size_t n = primitive_size(t.primitive);
        std::uint64_t raw = 0;
        if (v.kind == Value::Kind::kBool) {
          raw = v.b ? 1 : 0;
        } else if (v.kind == Value::Kind::kInt) {
          std::memcpy(&raw, &v.i, sizeof raw);
        } else if (v.kind == Value::Kind::kUInt) {
          raw = v.u;
        } else if (t.primitive == PrimitiveKind::kFloat) {
          const auto f = static_cast<float>(v.d);
          std::uint32_t bits = 0;
          std::memcpy(&bits, &f, sizeof bits);
          raw = bits;
        } else {
          std::memcpy(&raw, &v.d, sizeof raw);
        }
        if (n < 8) {
          raw &= (std::uint64_t{1} << (8 * n)) - 1;
        }
        put_unsigned(raw, n);
        break;
      }
      case TypeSpec::Kind::kEnum:
        put_unsigned(v.u, 4);
        break;
      case TypeSpec::Kind::kString:
        put_unsigned(v.s.size() + 1, 4);
        bytes.insert(bytes.end(), v.s.begin(), v.s.end());
        bytes.push_back(0);
        break;
      case TypeSpec::Kind::kSequence:
        put_unsigned(v.items.size(), 4);
        for (const auto& item : v.items) {
          write(*t.element, item);
        }
        break;
      case TypeSpec::Kind::kArray:
        for (const auto& item : v.items) {
          write(*t.element, item);
        }
        break;
      case TypeSpec::Kind::kStruct:
        write_struct(table_.get_struct(t.name), v, false);
        break;
    }
  }

  void write_struct(const StructDef& s, const Value& v, bool keys_only) {
    for (std::size_t k = 0; k < s.members.size() && k < v.fields.size(); ++k) {
      const Member& m = s.members[k];
      if (keys_only && !m.key) {
        continue;
      }
      if (keys_only && m.type.kind == TypeSpec::Kind::kStruct) {
        const StructDef& inner = table_.get_struct(m.type.name);
        write_struct(inner, v.fields[k].second, inner.has_key());
      } else {
        write(m.type, v.fields[k].second);
      }
    }
  }

 private:
  const TypeTable& table_;
};

}  // namespace

Value decode(const TypeTable& table, const std::string& type_name, const std::uint8_t* data,
             std::size_t size) {
  const StructDef& s = table.get_struct(type_name);
  if (data == nullptr && size != 0) {
    throw DecodeError("null payload");
  }
  Reader reader(table, data, size);
  std::string path;
  Value v = reader.read_struct(s, path);
  reader.finish(s.name);
  return v;
}

std::optional<std::string> payload_problem(const TypeTable& table, const std::string& type_name,
                                           const std::uint8_t* data, std::size_t size) {
  if (table.find_struct(type_name) == nullptr) {
    return std::nullopt;
  }
  try {
    (void)decode(table, type_name, data, size);
  } catch (const DecodeError& e) {
    return std::string(e.what());
  }
  return std::nullopt;
}

std::string to_json(const Value& value) {
  std::string out;
  append_json(out, value);
  return out;
}

std::string to_text(const Value& value) {
  std::string out;
  if (value.kind == Value::Kind::kStruct) {
    append_text_fields(out, value, 0, false);
  } else {
    append_text_value(out, value, 0);
  }
  return out;
}

std::vector<std::uint8_t> serialize_key_be(const TypeTable& table, const std::string& type_name,
                                           const Value& value) {
  KeyWriter w(table);
  w.write_struct(table.get_struct(type_name), value, true);
  return std::move(w.bytes);
}

std::optional<std::int64_t> read_header_stamp_ns(const std::uint8_t* data, std::size_t size) {
  if (data == nullptr || size < kEncapsulationSize + 8 || data[0] != 0 || data[1] > 1) {
    return std::nullopt;
  }
  const bool little = data[1] == 1;
  std::uint64_t raw = 0;
  for (std::size_t k = 0; k < 8; ++k) {
    const std::size_t byte = little ? k : 7 - k;
    raw |= static_cast<std::uint64_t>(data[kEncapsulationSize + k]) << (8 * byte);
  }
  std::int64_t out = 0;
  std::memcpy(&out, &raw, sizeof out);
  return out;
}

std::optional<std::int64_t> read_ros_header_stamp_ns(const std::uint8_t* data, std::size_t size) {
  if (data == nullptr || size < kEncapsulationSize + 8 || data[0] != 0 || data[1] > 1) {
    return std::nullopt;
  }
  const bool little = data[1] == 1;
  const auto u32 = [&](std::size_t at) {
    std::uint32_t v = 0;
    for (std::size_t k = 0; k < 4; ++k) {
      const std::size_t byte = little ? k : 3 - k;
      v |= static_cast<std::uint32_t>(data[kEncapsulationSize + at + k]) << (8 * byte);
    }
    return v;
  };
  std::int32_t sec = 0;
  const std::uint32_t raw_sec = u32(0);
  std::memcpy(&sec, &raw_sec, sizeof sec);
  const std::uint32_t nanosec = u32(4);
  if (sec < 0 || nanosec >= 1000000000U) {
    return std::nullopt;
  }
  return static_cast<std::int64_t>(sec) * 1000000000LL + nanosec;
}

bool has_ros_header_stamp(const TypeTable& table, const std::string& type_name) {
  const StructDef* s = table.find_struct(type_name);
  return s != nullptr && !s->members.empty() && s->members[0].type.kind == TypeSpec::Kind::kStruct &&
         s->members[0].type.name == "std_msgs::msg::dds_::Header_";
}

bool has_header_stamp(const TypeTable& table, const std::string& type_name) {
  const StructDef* s = table.find_struct(type_name);
  if (s == nullptr || s->members.empty() || s->members[0].type.kind != TypeSpec::Kind::kStruct) {
    return false;
  }
  const StructDef* h = table.find_struct(s->members[0].type.name);
  return h != nullptr && !h->members.empty() && h->members[0].name == "stamp_ns" &&
         h->members[0].type.kind == TypeSpec::Kind::kPrimitive &&
         h->members[0].type.primitive == PrimitiveKind::kInt64;
}

}  // namespace poise::schema
