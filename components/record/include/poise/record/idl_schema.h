// omgidl schemas for MCAP channels: one self-contained IDL text per type. The one flattener and
// the one embedded IDL table are schema's (poise/schema/idl_schema.h); this is the recorder's
// view of them.
#pragma once

#include "poise/schema/idl_schema.h"

#include <optional>
#include <string>

namespace poise::record {

/// The self-contained IDL text of SCOPED_NAME ("poise::msg::ImuSample") and every type it depends
/// on (TypeTable::flatten), or nullopt when `table` has no such struct.
inline std::optional<std::string> flattened_idl(
    const std::string& scoped_name, const schema::TypeTable& table = schema::TypeTable::builtin()) {
  if (table.find_struct(scoped_name) == nullptr) {
    return std::nullopt;
  }
  return table.flatten(scoped_name);
}

}  // namespace poise::record
