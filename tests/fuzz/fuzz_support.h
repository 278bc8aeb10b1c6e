// Shared by the configuration fuzz targets (fuzz_yaml, fuzz_config): the invariant "a loader
// returns or throws a std::exception that says why" and the input as a file for the loaders that
// take a path.
#pragma once

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>

namespace poise::fuzz {

/// Runs `f`; aborts (a finding) unless it returns or throws a std::exception with a message.
template <typename F>
void expect_returns_or_refuses(F f) {
  try {
    f();
  } catch (const std::exception& e) {
    if (e.what() == nullptr || e.what()[0] == '\0') std::abort();  // a refusal says why
  } catch (...) {
    std::abort();
  }
}

/// Writes `text` to a per-process file (ending in `suffix`) and returns its path, "" on failure.
inline std::string as_file(const std::string& text, const std::string& suffix = ".yaml") {
  const std::string path = "/tmp/poise_fuzz_" + std::to_string(::getpid()) + suffix;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) return "";
  std::fwrite(text.data(), 1, text.size(), f);
  std::fclose(f);
  return path;
}

}  // namespace poise::fuzz
