// Little-endian encoding helpers for MCAP records (internal).
#pragma once

#include "poise/record/mcap.h"

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace poise::record::detail {

inline void put_u8(std::vector<uint8_t>& out, uint8_t v) { out.push_back(v); }
inline void put_u16(std::vector<uint8_t>& out, uint16_t v) {
  out.push_back(static_cast<uint8_t>(v & 0xFFu));
  out.push_back(static_cast<uint8_t>(v >> 8));
}
inline void put_u32(std::vector<uint8_t>& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) {
    out.push_back(static_cast<uint8_t>((v >> (8 * i)) & 0xFFu));
  }
}
inline void put_u64(std::vector<uint8_t>& out, uint64_t v) {
  for (int i = 0; i < 8; ++i) {
    out.push_back(static_cast<uint8_t>((v >> (8 * i)) & 0xFFu));
  }
}
inline void put_string(std::vector<uint8_t>& out, const std::string& s) {
  put_u32(out, static_cast<uint32_t>(s.size()));
  out.insert(out.end(), s.begin(), s.end());
}
inline void put_bytes32(std::vector<uint8_t>& out, const std::vector<uint8_t>& b) {
  put_u32(out, static_cast<uint32_t>(b.size()));
  out.insert(out.end(), b.begin(), b.end());
}
/// Starts a record: opcode + a length placeholder; returns the position to patch.
inline size_t begin_record(std::vector<uint8_t>& out, Opcode op) {
  out.push_back(static_cast<uint8_t>(op));
  const size_t at = out.size();
  put_u64(out, 0);
  return at;
}
inline void end_record(std::vector<uint8_t>& out, size_t at) {
  const uint64_t len = out.size() - at - 8;
  for (int i = 0; i < 8; ++i) {
    out[at + static_cast<size_t>(i)] = static_cast<uint8_t>((len >> (8 * i)) & 0xFFu);
  }
}

inline uint16_t get_u16(const uint8_t* p) {
  return static_cast<uint16_t>(p[0] | (p[1] << 8));
}
inline uint32_t get_u32(const uint8_t* p) {
  return static_cast<uint32_t>(p[0]) | (static_cast<uint32_t>(p[1]) << 8) |
         (static_cast<uint32_t>(p[2]) << 16) | (static_cast<uint32_t>(p[3]) << 24);
}
inline uint64_t get_u64(const uint8_t* p) {
  return static_cast<uint64_t>(get_u32(p)) | (static_cast<uint64_t>(get_u32(p + 4)) << 32);
}

/// Bounds-checked cursor over a record body; every getter throws ReadError past the end.
class Parser {
 public:
  Parser(const uint8_t* data, size_t size, const char* what) : p_(data), n_(size), what_(what) {}
  uint8_t u8() { need(1); return p_[pos_++]; }
  uint16_t u16() { need(2); const uint16_t v = get_u16(p_ + pos_); pos_ += 2; return v; }
  uint32_t u32() { need(4); const uint32_t v = get_u32(p_ + pos_); pos_ += 4; return v; }
  uint64_t u64() { need(8); const uint64_t v = get_u64(p_ + pos_); pos_ += 8; return v; }
  std::string str() {
    const uint32_t len = u32();
    need(len);
    std::string s(reinterpret_cast<const char*>(p_ + pos_), len);
    pos_ += len;
    return s;
  }
  std::vector<uint8_t> bytes32() {
    const uint32_t len = u32();
    need(len);
    std::vector<uint8_t> b(p_ + pos_, p_ + pos_ + len);
    pos_ += len;
    return b;
  }
  void skip(uint64_t n) { need(n); pos_ += static_cast<size_t>(n); }
  [[nodiscard]] size_t pos() const { return pos_; }
  [[nodiscard]] size_t left() const { return n_ - pos_; }
  [[nodiscard]] const uint8_t* here() const { return p_ + pos_; }
  void need(uint64_t k) const {
    if (k > n_ - pos_) {
      throw ReadError(std::string(what_) + " record is shorter than its fields (needs " +
                      std::to_string(k) + " more bytes at field offset " + std::to_string(pos_) +
                      ", has " + std::to_string(n_ - pos_) + ")");
    }
  }

 private:
  const uint8_t* p_;
  size_t n_;
  size_t pos_ = 0;
  const char* what_;
};

inline const char* opcode_name(uint8_t op) {
  switch (op) {
    case 0x01: return "Header";
    case 0x02: return "Footer";
    case 0x03: return "Schema";
    case 0x04: return "Channel";
    case 0x05: return "Message";
    case 0x06: return "Chunk";
    case 0x07: return "Message Index";
    case 0x08: return "Chunk Index";
    case 0x09: return "Attachment";
    case 0x0A: return "Attachment Index";
    case 0x0B: return "Statistics";
    case 0x0C: return "Metadata";
    case 0x0D: return "Metadata Index";
    case 0x0E: return "Summary Offset";
    case 0x0F: return "Data End";
    default: return "unknown";
  }
}

}  // namespace poise::record::detail
