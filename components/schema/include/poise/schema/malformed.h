// Malformed variants of a valid payload: what a hostile or broken participant may publish under a
// poise type name. Used by the hidden test publisher (`poise dds-test-pub --type imu-malformed`)
// and the tests that show the tools and nodes count and reject them instead of crashing.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace poise::schema {

struct MalformedPayload {
  std::string name;  ///< what is wrong, e.g. "truncated to 12 bytes"
  std::vector<std::uint8_t> bytes;
};

/// Variants of `valid` (a little-endian poise payload without end padding, as fastcdr serializes
/// it: 4-byte encapsulation, then `Header` whose frame_id length is at byte 16) that no decoder
/// may accept: truncations to 0, 4, 12, 60 and 136 bytes (those shorter than `valid`), a big-endian header on a
/// little-endian body, an unknown encapsulation, frame_id lengths 0, 100 and 0xFFFFFFFF, a
/// frame_id without its NUL, and 8 trailing bytes.
std::vector<MalformedPayload> malformed_variants(const std::vector<std::uint8_t>& valid);

}  // namespace poise::schema
