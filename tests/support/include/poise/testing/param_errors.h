// For parameter validation tests: a bad value (ParamCheck's shape: "<filter> parameter <key> must
// be ...") and an unknown key (the one shape of every loader, poise/core/yaml_params.h:
// "<where>: unknown key '<key>' (known: ...)").
#pragma once

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace poise::testing {

/// The message of the `Exception` that `f()` throws; "" when it throws none (another exception
/// type propagates).
template <typename Exception, typename F>
std::string message_of(F&& f) {
  try {
    f();
  } catch (const Exception& e) {
    return e.what();
  }
  return "";
}

/// The message of the std::invalid_argument that `make()` throws; "" when it throws none.
template <typename F>
std::string invalid_argument_message(F&& make) {
  return message_of<std::invalid_argument>(make);
}

/// The message of the std::exception that `load()` throws; "" when it throws none.
template <typename F>
std::string error_message(F&& load) {
  return message_of<std::exception>(load);
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

/// `message` is the one unknown-key message: "<where>: unknown key '<key>' (known: ...)" whose
/// list holds every one of `allowed` (some of the keys that are allowed at that place).
inline void expect_unknown_key_message(const std::string& message, const std::string& where, const std::string& key,
                                       const std::vector<std::string>& allowed) {
  const std::string head = where + ": unknown key '" + key + "' (known: ";
  const auto at = message.find(head);
  ASSERT_NE(at, std::string::npos) << "expected \"" << head << "...)\" in: " << message;
  const auto end = message.find(')', at + head.size());
  ASSERT_NE(end, std::string::npos) << message;
  const std::string list = ", " + message.substr(at + head.size(), end - at - head.size()) + ",";
  for (const auto& k : allowed) {
    EXPECT_NE(list.find(", " + k + ","), std::string::npos) << "'" << k << "' not listed in: " << message;
  }
}

}  // namespace poise::testing
