// Every header a user gets from the packages compiles on its own (docs/DEPLOY.md "Building against
// the installed headers"): this build tree is installed with `cmake --install --component dev`
// (what poise-dev holds) and `--component dds` (poise-dds-dev) into a temporary prefix, and each
// installed header is compiled alone (-fsyntax-only, -Wall -Wextra -Werror) with nothing but the
// flags a user has: `pkg-config --cflags poise-cores` for the cores, plus the include directories
// of the exported poise::idl / poise::dds targets for the DDS layer. The headers expected are the
// ones in the source tree's core and DDS include folders; evaluation and command-line code
// (tools/poise/) must not be installed at all.
#include "poise/testing/npm.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace poise::testing {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

constexpr auto kInstallTimeout = 120s;
constexpr auto kCompileTimeout = 120s;  // one header, Eigen or Fast DDS included

/// A temporary install prefix, removed at the end of the test.
class Prefix {
 public:
  Prefix() {
    const char* t = std::getenv("TMPDIR");
    std::string pattern = std::string(t != nullptr && *t != '\0' ? t : "/tmp") + "/poise-prefix-XXXXXX";
    char* made = ::mkdtemp(pattern.data());
    if (made == nullptr) {
      throw std::runtime_error("mkdtemp failed for " + pattern);
    }
    path_ = made;
  }
  ~Prefix() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  Prefix(const Prefix&) = delete;
  Prefix& operator=(const Prefix&) = delete;
  [[nodiscard]] const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

/// `cmake --install` of this build tree, one CPack component, into `prefix`; "" or the failure.
std::string install_component(const fs::path& prefix, const std::string& component) {
  const RunResult r = run({POISE_CMAKE_COMMAND, "--install", POISE_INSTALL_BINARY_DIR, "--component",
                           component, "--prefix", prefix.string()},
                          kInstallTimeout);
  return r.exit_code == 0 ? "" : "cmake --install --component " + component + " failed:\n" + r.output;
}

/// Headers (*.h) below `dir`, relative to `dir`, sorted.
std::vector<std::string> headers_under(const fs::path& dir) {
  std::vector<std::string> out;
  if (!fs::is_directory(dir)) {
    return out;
  }
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file() && e.path().extension() == ".h") {
      out.push_back(fs::relative(e.path(), dir).string());
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

/// The headers of the source tree's include folders `dirs` (each relative to the source root),
/// as installed: relative to the include folder.
std::vector<std::string> source_headers(const std::vector<std::string>& dirs) {
  std::vector<std::string> out;
  for (const auto& d : dirs) {
    for (const auto& h : headers_under(source_path(d))) {
      out.push_back(h);
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> split_words(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::string> out;
  for (std::string w; in >> w;) {
    out.push_back(w);
  }
  return out;
}

/// Compiles each header under `include_dir` listed in `headers` alone with `flags`; returns the
/// failures (header and compiler output).
std::vector<std::string> compile_each(const fs::path& include_dir, const std::vector<std::string>& headers,
                                      const std::vector<std::string>& flags) {
  std::vector<std::string> failures;
  for (const auto& h : headers) {
    std::vector<std::string> argv{POISE_CXX_COMPILER, "-std=c++17", "-fsyntax-only", "-Wall",
                                  "-Wextra", "-Werror"};
    argv.insert(argv.end(), flags.begin(), flags.end());
    // as a user's file that includes it first and nothing else (-include: the header is not the
    // main file, so `#pragma once` is not warned about)
    argv.insert(argv.end(), {"-include", (include_dir / h).string(), "-x", "c++", "/dev/null"});
    const RunResult r = run(argv, kCompileTimeout);
    if (r.exit_code != 0) {
      failures.push_back(h + ":\n" + r.output);
    }
  }
  return failures;
}

std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) {
    s += x + "\n";
  }
  return s;
}

const std::vector<std::string> kCoreIncludeDirs{
    "components/core/include",
    "components/estimators/parallel_kf/include",
    "components/estimators/gauss_newton/include",
    "components/estimators/selective_ekf/include",
    "components/estimators/altitude/include",
    "components/estimators/vehicle/include",
};

/// Headers of the evaluation and command-line code (tools/poise/*/include), never installed.
std::vector<std::string> tools_headers() {
  std::vector<std::string> dirs;
  for (const auto& e : fs::directory_iterator(source_path("tools/poise"))) {
    if (fs::is_directory(e.path() / "include")) {
      dirs.push_back(fs::relative(e.path() / "include", source_path("")).string());
    }
  }
  return source_headers(dirs);
}

}  // namespace

TEST(InstalledHeaders, GivenTheCoresInstalledThenExactlyTheCoreHeadersAreThereAndNoEvaluationOrCliHeader) {
  Prefix prefix;
  const std::string problem = install_component(prefix.path(), "dev");
  ASSERT_EQ(problem, "");
  const auto installed = headers_under(prefix.path() / "include");
  const auto expected = source_headers(kCoreIncludeDirs);
  EXPECT_EQ(joined(installed), joined(expected));
  std::vector<std::string> leaked;
  for (const auto& h : tools_headers()) {
    if (std::binary_search(installed.begin(), installed.end(), h)) {
      leaked.push_back(h);
    }
  }
  EXPECT_TRUE(leaked.empty()) << "evaluation / command-line headers installed:\n" << joined(leaked);
  std::cout << "poise-dev installs " << installed.size() << " headers\n";
}

TEST(InstalledHeaders, GivenTheCoresInstalledWhenEachHeaderIsCompiledAloneWithPkgConfigCflagsThenEveryOneCompiles) {
  const std::string pkg_config = find_on_path("pkg-config");
  if (pkg_config.empty()) {
    POISE_SKIP("pkg-config is not on PATH (Debian pkg-config): the installed poise-cores.pc cannot be read");
  }
  Prefix prefix;
  const std::string problem = install_component(prefix.path(), "dev");
  ASSERT_EQ(problem, "");
  const RunResult cflags = run({pkg_config, "--cflags", "poise-cores"}, 30s,
                               {"PKG_CONFIG_PATH=" + (prefix.path() / "lib/pkgconfig").string()});
  ASSERT_EQ(cflags.exit_code, 0) << cflags.output;
  const auto headers = headers_under(prefix.path() / "include");
  ASSERT_FALSE(headers.empty());
  const auto failures = compile_each(prefix.path() / "include", headers, split_words(cflags.output));
  EXPECT_TRUE(failures.empty()) << failures.size() << " of " << headers.size()
                                << " installed headers do not compile alone:\n"
                                << joined(failures);
  std::cout << headers.size() - failures.size() << " of " << headers.size()
            << " installed core headers compile alone with `pkg-config --cflags poise-cores` ("
            << cflags.output.substr(0, cflags.output.find('\n')) << ")\n";
}

TEST(InstalledHeaders, GivenTheDdsLayerInstalledWhenEachHeaderIsCompiledAloneThenEveryOneCompiles) {
  const std::string pkg_config = find_on_path("pkg-config");
  if (pkg_config.empty()) {
    POISE_SKIP("pkg-config is not on PATH (Debian pkg-config): the installed poise-cores.pc cannot be read");
  }
  Prefix prefix;
  for (const char* component : {"dev", "dds"}) {  // poise-dds-dev depends on poise-dev
    const std::string problem = install_component(prefix.path(), component);
    ASSERT_EQ(problem, "");
  }
  const RunResult cflags = run({pkg_config, "--cflags", "poise-cores"}, 30s,
                               {"PKG_CONFIG_PATH=" + (prefix.path() / "lib/pkgconfig").string()});
  ASSERT_EQ(cflags.exit_code, 0) << cflags.output;
  // What the exported poise::idl adds (cmake/PoiseInstall.cmake): the generated headers include
  // each other by bare names.
  auto flags = split_words(cflags.output);
  const fs::path include = prefix.path() / "include";
  flags.push_back("-I" + (include / "poise/msg").string());
  flags.push_back("-I" + (include / "poise/ros2").string());
  std::vector<std::string> headers;
  for (const char* area : {"poise/dds", "poise/msg", "poise/ros2"}) {
    for (const auto& h : headers_under(include / area)) {
      headers.push_back(std::string(area) + "/" + h);
    }
  }
  // The generated type support: one header and one PubSubTypes header per IDL file.
  std::size_t idl_files = 0;
  for (const char* idl_dir : {"idl", "idl/ros2"}) {
    for (const auto& e : fs::directory_iterator(source_path(idl_dir))) {
      idl_files += e.path().extension() == ".idl" ? 1U : 0U;
    }
  }
  const auto dds_headers = source_headers({"components/dds/include"});
  EXPECT_EQ(headers.size(), dds_headers.size() + 2 * idl_files);
  const auto failures = compile_each(include, headers, flags);
  EXPECT_TRUE(failures.empty()) << failures.size() << " of " << headers.size()
                                << " installed DDS headers do not compile alone:\n"
                                << joined(failures);
  std::cout << headers.size() - failures.size() << " of " << headers.size()
            << " installed DDS-layer headers (poise/dds, poise/msg, poise/ros2) compile alone\n";
}

}  // namespace poise::testing
