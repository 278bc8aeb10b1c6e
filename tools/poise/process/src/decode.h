// Decoding one recorded payload of a poise type: the one payload check
// (schema::payload_problem: bounds, encapsulation, strings, trailing bytes), then fastcdr.
#pragma once

#include "poise/schema/cdr.h"
#include "poise/record/mcap.h"

#include <fastdds/rtps/common/SerializedPayload.h>

#include <cstring>
#include <exception>
#include <optional>
#include <string>

namespace poise::record {

/// Decodes `m` (its schema names the type) into `out`; the problem when it is malformed.
template <typename PubSubType>
std::optional<std::string> decode(const MessageView& m, typename PubSubType::type& out) {
  std::optional<std::string> problem =
      schema::payload_problem(schema::TypeTable::builtin(), m.schema->name, m.data, m.size);
  if (problem) {
    return problem;
  }
  PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<uint32_t>(m.size));
  std::memcpy(payload.data, m.data, m.size);
  payload.length = static_cast<uint32_t>(m.size);
  try {
    if (!type.deserialize(&payload, &out)) {
      return std::string("fastcdr could not deserialize it");
    }
  } catch (const std::exception& e) {
    return std::string("fastcdr: ") + e.what();
  }
  return std::nullopt;
}

}  // namespace poise::record
