#include "poise/schema/malformed.h"

#include <cstddef>

namespace poise::schema {

namespace {

constexpr std::size_t kFrameIdLengthAt = 16;  // 4 encapsulation + int64 stamp_ns + uint32 seq

void put_u32_le(std::vector<std::uint8_t>& bytes, std::size_t at, std::uint32_t v) {
  for (std::size_t k = 0; k < 4; ++k) {
    bytes[at + k] = static_cast<std::uint8_t>(v >> (8 * k));
  }
}

std::uint32_t get_u32_le(const std::vector<std::uint8_t>& bytes, std::size_t at) {
  std::uint32_t v = 0;
  for (std::size_t k = 0; k < 4; ++k) {
    v |= static_cast<std::uint32_t>(bytes[at + k]) << (8 * k);
  }
  return v;
}

}  // namespace

std::vector<MalformedPayload> malformed_variants(const std::vector<std::uint8_t>& valid) {
  std::vector<MalformedPayload> out;
  for (const std::size_t n : {0, 4, 12, 60, 136}) {
    if (n < valid.size()) {
      out.push_back({"truncated to " + std::to_string(n) + " bytes",
                     std::vector<std::uint8_t>(valid.begin(), valid.begin() + n)});
    }
  }
  if (valid.size() < kFrameIdLengthAt + 8) {
    return out;
  }
  auto big_endian = valid;
  big_endian[1] = 0x00;
  out.push_back({"big-endian header on a little-endian body", big_endian});
  auto unknown = valid;
  unknown[1] = 0x07;
  out.push_back({"unknown encapsulation 0x0007", unknown});
  for (const std::uint32_t length : {0U, 100U, 0xFFFFFFFFU}) {
    auto bad = valid;
    put_u32_le(bad, kFrameIdLengthAt, length);
    out.push_back({"frame_id length " + std::to_string(length), bad});
  }
  const std::uint32_t length = get_u32_le(valid, kFrameIdLengthAt);
  if (length > 0 && kFrameIdLengthAt + 4 + length <= valid.size()) {
    auto no_nul = valid;
    no_nul[kFrameIdLengthAt + 4 + length - 1] = 'x';
    out.push_back({"frame_id without NUL", no_nul});
  }
  auto trailing = valid;
  trailing.insert(trailing.end(), 8, 0xAB);
  out.push_back({"8 trailing bytes", trailing});
  return out;
}

}  // namespace poise::schema
