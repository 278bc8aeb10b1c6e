// For parameter validation tests (ParamCheck's shape: "<filter> parameter <key> must be ...").
#pragma once

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace poise::testing {

/// The message of the std::invalid_argument that `make()` throws; "" when it throws none.
template <typename F>
std::string invalid_argument_message(F&& make) {
  try {
    make();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

/// One bad value: the key (as in the YAML file) and how to spoil a valid Params with it.
template <typename Params>
using BadValue = std::pair<const char*, void (*)(Params&)>;

/// For each case: `base` spoiled by it must make `build(params)` throw std::invalid_argument whose
/// message reads "<filter> parameter <key> must be" (a startup error naming the key).
template <typename Params, typename Build>
void expect_bad_values_name_their_keys(const char* filter, const Params& base,
                                       const std::vector<BadValue<Params>>& cases, Build build) {
  for (const auto& [key, spoil] : cases) {
    Params p = base;
    spoil(p);
    const std::string msg = invalid_argument_message([&] { build(p); });
    EXPECT_NE(msg.find(std::string(filter) + " parameter " + key + " must be"), std::string::npos)
        << key << ": " << msg;
  }
}

}  // namespace poise::testing
