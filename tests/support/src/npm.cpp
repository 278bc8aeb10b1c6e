#include "poise/testing/npm.h"

#include "poise/testing/testing.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>

namespace poise::testing {

std::string find_on_path(const std::string& exe) {
  const char* path = std::getenv("PATH");
  const std::string p = path != nullptr ? path : "/usr/bin:/bin";
  std::size_t start = 0;
  while (start <= p.size()) {
    const std::size_t end = p.find(':', start);
    const std::string dir = p.substr(start, end == std::string::npos ? std::string::npos : end - start);
    const std::string candidate = (dir.empty() ? "." : dir) + "/" + exe;
    if (::access(candidate.c_str(), X_OK) == 0) {
      return candidate;
    }
    if (end == std::string::npos) {
      break;
    }
    start = end + 1;
  }
  return "";
}

std::string npm_install(const std::string& dir, const std::vector<std::string>& packages) {
  using namespace std::chrono_literals;
  const std::string npm = find_on_path("npm");
  if (find_on_path("node").empty() || npm.empty()) {
    return "node/npm not found on PATH: the independent JavaScript checker cannot run (install nodejs and npm)";
  }
  const int lock = ::open((dir + "/.install.lock").c_str(), O_CREAT | O_RDWR, 0644);
  if (lock >= 0) {
    ::flock(lock, LOCK_EX);
  }
  std::string problem;
  bool installed = true;
  for (const auto& pkg : packages) {
    struct stat st {};
    if (::stat((dir + "/node_modules/" + pkg + "/package.json").c_str(), &st) != 0) {
      installed = false;
    }
  }
  if (!installed) {
    const auto install = run({npm, "install", "--prefix", dir, "--no-audit", "--no-fund", "--loglevel=error"}, 180s);
    if (install.exit_code != 0) {
      problem = "npm install in " + dir + " failed (exit " + std::to_string(install.exit_code) +
                ", offline?): " + install.output.substr(0, 600);
    }
  }
  if (lock >= 0) {
    ::flock(lock, LOCK_UN);
    ::close(lock);
  }
  return problem;
}

}  // namespace poise::testing
