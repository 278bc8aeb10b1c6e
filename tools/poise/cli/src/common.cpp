#include "poise/cli/common.h"

#include <atomic>
#include <csignal>
#include <ctime>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <map>
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
  *domain = 0;
  CLI::Option* opt = sub->add_option("--domain", *domain, "DDS domain id (default: $POISE_DOMAIN, else 0)")
                         ->check(CLI::Range(0, kMaxDomain));
  on_parsed(sub, [opt, domain] {
    if (opt->count() == 0) {
      *domain = default_domain();
    }
  });
  return opt;
}

void on_parsed(CLI::App* sub, std::function<void()> check) {
  // One parse-complete callback per command runs every check in order. CLI11 runs it after the
  // command's --help was handled (a check never breaks --help) and before its final callback.
  static std::map<const CLI::App*, std::vector<std::function<void()>>> checks;
  auto& list = checks[sub];
  if (list.empty()) {
    sub->parse_complete_callback([sub] {
      for (const auto& c : checks[sub]) {
        c();
      }
    });
  }
  list.push_back(std::move(check));
}

CLI::Option* add_output_file_option(CLI::App* sub, std::string* path, const std::string& what, bool required) {
  CLI::Option* opt = sub->add_option("-o,--output", *path, "Output file: " + what);
  if (required) {
    opt->required();
  }
  return opt;
}

CLI::Option* add_out_dir_option(CLI::App* sub, std::string* dir, const std::string& what, bool required) {
  CLI::Option* opt = sub->add_option("--out-dir", *dir, "Output directory: " + what);
  if (required) {
    opt->required();
  }
  return opt;
}

CLI::Option* add_dds_profile_option(CLI::App* sub, std::string* profile) {
  return sub->add_option("--dds-profile", *profile,
                         "DDS participant profile: poise_default, poise_udp, poise_loopback or one of "
                         "$POISE_QOS_FILE (default: $POISE_DDS_PROFILE, else poise_default)");
}

void deprecation_note(const CLI::App* sub, const std::string& old_name, const std::string& new_name) {
  std::string path = sub->get_name();
  for (const CLI::App* p = sub->get_parent(); p != nullptr && p->get_parent() != nullptr; p = p->get_parent()) {
    path = p->get_name() + " " + path;
  }
  std::cerr << "poise: note: 'poise " << path << " " << old_name << "' is deprecated, use " << new_name
            << " (accepted until poise 0.2)\n";
}

void require_one_of(CLI::App* sub, std::vector<CLI::Option*> options) {
  on_parsed(sub, [options] {
    for (const CLI::Option* o : options) {
      if (o->count() > 0) {
        return;
      }
    }
    throw CLI::RequiredError(options.front()->get_name());
  });
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
