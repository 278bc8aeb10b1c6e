// Test-side npm packages (independent checkers written in JavaScript: the MCAP validator, the
// Foxglove clients). The package.json is copied into the build tree by CMake; the packages are
// installed there at test time, once, under a lock (never at configure or build time, never into
// the source tree).
#pragma once

#include <string>
#include <vector>

namespace poise::testing {

/// node and npm on PATH, and the packages installed in `dir` (npm install --prefix DIR when one of
/// `packages` is missing). Returns "" when ready, else why not (the caller skips, or fails under
/// require_all()).
std::string npm_install(const std::string& dir, const std::vector<std::string>& packages);

/// An executable on PATH ("" when none).
std::string find_on_path(const std::string& exe);

}  // namespace poise::testing
