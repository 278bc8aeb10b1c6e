#include "poise/cli/common.h"

#include <atomic>
#include <csignal>
#include <cstdlib>
#include <functional>
#include <mutex>

namespace poise::cli {
namespace {
constexpr int kMaxDomain = 232;  // highest domain id whose RTPS ports fit in 16 bits
std::atomic<bool> g_stop{false};

extern "C" void on_stop_signal(int /*signal*/) { g_stop.store(true); }
}  // namespace

int default_domain() {
  const char* env = std::getenv("POISE_DOMAIN");
  if (env == nullptr || *env == '\0') {
    return 0;
  }
  char* end = nullptr;
  const long value = std::strtol(env, &end, 10);
  if (*end != '\0' || value < 0 || value > kMaxDomain) {
    throw Error("POISE_DOMAIN='" + std::string(env) + "' is not a domain id (0-" +
                std::to_string(kMaxDomain) + ")");
  }
  return static_cast<int>(value);
}

CLI::Option* add_domain_option(CLI::App* sub, int* domain) {
  *domain = default_domain();
  return sub->add_option("--domain", *domain, "DDS domain id (default: $POISE_DOMAIN, else 0)")
      ->check(CLI::Range(0, kMaxDomain))
      ->capture_default_str();
}

CLI::App* subcommand_group(CLI::App& parent, const std::string& name,
                           const std::string& description) {
  const auto matches = parent.get_subcommands(
      std::function<bool(CLI::App*)>([&name](CLI::App* sub) { return sub->get_name() == name; }));
  if (!matches.empty()) {
    return matches.front();
  }
  CLI::App* group = parent.add_subcommand(name, description);
  group->require_subcommand(1);
  return group;
}

bool stop_requested() { return g_stop.load(); }

void request_stop() { g_stop.store(true); }

void install_stop_handlers() {
  static std::once_flag once;
  std::call_once(once, [] {
    struct sigaction action {};
    action.sa_handler = on_stop_signal;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
  });
}

}  // namespace poise::cli
