#include "poise/runtime/shipped.h"

#include <filesystem>
#include <system_error>

namespace poise::runtime {
namespace fs = std::filesystem;

std::string shipped_config_dir_of(const std::string& exe) {
  if (exe.empty()) {
    return "";
  }
  const fs::path dir = (fs::path(exe).parent_path() / ".." / "share" / "poise").lexically_normal();
  std::error_code ec;
  return fs::is_directory(dir, ec) ? dir.string() : "";
}

std::string shipped_config_dir() {
  static const std::string dir = [] {
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    return ec ? std::string() : shipped_config_dir_of(exe.string());
  }();
  return dir;
}

std::string shipped_file_hint(const std::string& relative) {
  const std::string dir = shipped_config_dir();
  if (!dir.empty()) {
    return (fs::path(dir) / relative).string();
  }
  return relative + " of the shipped configuration (config/" + relative + " in the source tree)";
}

}  // namespace poise::runtime
