// omgidl schemas for MCAP channels: one self-contained IDL text per type, built from the project's
// idl/*.idl (embedded at build time) without preprocessor directives.
#pragma once

#include <map>
#include <optional>
#include <string>

namespace poise::record {

/// The IDL files built into this binary: file name ("imu.idl") -> text.
const std::map<std::string, std::string>& builtin_idl_files();

/// A self-contained IDL text defining SCOPED_NAME ("poise::msg::ImuSample"): the file that
/// defines it preceded by everything it #includes (transitively, each file once, included files
/// first), with preprocessor lines removed. nullopt if no file defines it.
std::optional<std::string> flattened_idl(
    const std::string& scoped_name,
    const std::map<std::string, std::string>& files = builtin_idl_files());

}  // namespace poise::record
