// `poise run HOST.yaml` and the generated `poise <component>` commands.
#include "poise/cli/common.h"
#include "poise/runtime/host.h"
#include "poise/core/yaml_params.h"
#include "poise/runtime/realtime.h"
#include "poise/runtime/service.h"
#include "poise/runtime/shipped.h"

#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

namespace poise::cli {
namespace {

struct RunOptions {
  int domain = 0;
  CLI::Option* domain_option = nullptr;
  std::string profile;  // "" = the host file's participant_profile, else $POISE_DDS_PROFILE
  double duration_s = 0.0;  // 0 = until SIGINT/SIGTERM
  double status_period_s = 2.0;
  bool quiet = false;
  int rt_priority = -1;  // -1: the host file's
  std::string cpus;      // empty: the host file's
  bool lock_memory = false;
};

/// Runs a host until a signal, the duration, or a failure; prints status periodically.
void run_host(const runtime::HostSpec& host_spec, const RunOptions& options) {
  runtime::HostSpec spec = host_spec;
  if (!options.profile.empty()) {
    spec.participant_profile = options.profile;
  }
  const int domain = (options.domain_option != nullptr && options.domain_option->count() > 0)
                         ? options.domain
                         : spec.domain.value_or(options.domain);
  install_stop_handlers();
  runtime::RealtimeSettings rt = spec.realtime;
  if (options.rt_priority >= 0) {
    rt.priority = options.rt_priority;
  }
  if (!options.cpus.empty()) {
    rt.cpus = runtime::parse_cpu_list(options.cpus, "--cpus");
  }
  rt.lock_memory = rt.lock_memory || options.lock_memory;
  if (rt.any()) {  // before the participant: Fast DDS's threads inherit what is applied here
    const auto warnings = runtime::apply_realtime(rt);
    for (const auto& w : warnings) {
      std::fprintf(stderr, "poise: warning: real-time: %s\n", w.c_str());
    }
    if (warnings.empty() && !options.quiet) {
      std::fprintf(stderr, "poise: real-time: %s\n", runtime::describe(rt).c_str());
    }
  }
  runtime::Host host(spec, domain);
  runtime::start_and_notify(host);  // READY=1 to systemd only once every component has started
  if (!options.quiet) {
    std::fprintf(stderr, "poise: %zu component(s) running on domain %d (Ctrl-C stops)\n",
                 spec.components.size(), domain);
  }
  const auto start = std::chrono::steady_clock::now();
  const auto ns_of = [](std::chrono::steady_clock::time_point t) {
    return static_cast<int64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count());
  };
  // fed only while every component produces (systemd's WatchdogSec=; off otherwise)
  runtime::ServiceWatchdog watchdog([&host] { return host.produced(); },
                                    runtime::ServiceWatchdog::interval_from_environment(), ns_of(start));
  auto next_status = start + std::chrono::duration<double>(options.status_period_s);
  while (!stop_requested()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const auto now = std::chrono::steady_clock::now();
    watchdog.poll(ns_of(now));
    if (options.duration_s > 0.0 &&
        std::chrono::duration<double>(now - start).count() >= options.duration_s) {
      break;
    }
    if (!options.quiet && now >= next_status) {
      for (const auto& line : host.status()) {
        std::fprintf(stderr, "  %s\n", line.c_str());
      }
      next_status += std::chrono::duration<double>(options.status_period_s);
    }
  }
  runtime::stop_and_notify(host);
  if (!options.quiet) {
    std::fprintf(stderr, "poise: stopped cleanly\n");
  }
}

void add_run_options(CLI::App* sub, RunOptions& options) {
  options.domain_option = add_domain_option(sub, &options.domain);
  add_dds_profile_option(sub, &options.profile);
  sub->add_option("--duration", options.duration_s, "Stop after this many seconds (0: run until Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--status-period", options.status_period_s, "Seconds between status lines")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  sub->add_flag("--quiet", options.quiet, "No status output");
  sub->add_option("--rt-priority", options.rt_priority,
                  "SCHED_FIFO priority 1-99 for every thread (0: normal; default: the host file's realtime.priority)")
      ->check(CLI::Range(0, 99));
  sub->add_option("--cpus", options.cpus, "CPU affinity, e.g. 2,3 or 0-3 (default: the host file's realtime.cpus)");
  sub->add_flag("--lock-memory", options.lock_memory, "mlockall: no page faults on the sensor path");
}

std::string dashed(std::string name) {
  for (char& c : name) {
    if (c == '_') {
      c = '-';
    }
  }
  return name;
}

/// Parses `key=value` into a YAML scalar/sequence (the value is read as YAML: 1.5, true, [1,2]).
void set_param(YAML::Node& params, const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0) {
    throw Error("--set expects key=value, got '" + assignment + "'", kUsageExitCode);
  }
  try {
    params[assignment.substr(0, eq)] = parse_yaml(assignment.substr(eq + 1), "--set " + assignment);
  } catch (const std::runtime_error& e) {
    throw Error("--set " + assignment + ": " + e.what(), kUsageExitCode);
  }
}

// `poise <component>`: one component type run alone (one process), its parameters from --config,
// --set and the type's own command options.
void add_standalone_command(CLI::App& app, const std::string& type_name, const runtime::ComponentType& type) {
  struct Standalone {
    RunOptions run;
    std::string name;
    std::string config;
    std::vector<std::string> sets;
    std::vector<std::string> topics;
    std::map<std::string, std::string> options;  ///< command option key -> value given
  };
  auto s = std::make_shared<Standalone>();
  CLI::App* sub = app.add_subcommand(type.command.empty() ? dashed(type_name) : type.command,
                                     type.description + " (runs alone)");
  sub->add_option("--name", s->name, "Instance name (sensor_id of its outputs; default: " +
                                          type_name + ")");
  sub->add_option("--config", s->config, "Parameter file (YAML map)")->check(CLI::ExistingFile);
  sub->add_option("--set", s->sets,
                  "KEY=VALUE: parameter override, as in a host file's params (VALUE is YAML; e.g. "
                  "declination_deg=3.4); repeatable")
      ->allow_extra_args(false)
      ->type_name("KEY=VALUE");
  sub->add_option("--topic", s->topics, "Topic name override key=name, e.g. imu=imu2 (repeatable)");
  std::vector<std::pair<CLI::Option*, std::string>> key_options;  // the type's command options
  for (const auto& opt : type.command_options) {
    key_options.emplace_back(sub->add_option(opt.flag, s->options[opt.key], opt.help + " (= --set " + opt.key + "=VALUE)")
                                 ->type_name(opt.type_name),
                             opt.key);
  }
  add_run_options(sub, s->run);  // --domain, --dds-profile, ...
  add_deprecated_alias(sub, "--profile", "--dds-profile", &s->run.profile);
  const std::string key = type_name;
  const std::string command = sub->get_name();
  sub->callback([s, key, command, key_options] {
    runtime::HostSpec spec;  // the profile: --dds-profile, applied by run_host
    runtime::ComponentSpec c;
    c.type = key;
    c.name = s->name.empty() ? key : s->name;
    c.origin = "poise " + command;
    c.params = s->config.empty() ? YAML::Node(YAML::NodeType::Map)
                                 : runtime::load_param_file(s->config);
    for (const auto& assignment : s->sets) {
      set_param(c.params, assignment);
    }
    for (const auto& [option, param] : key_options) {
      if (option->count() == 0) {
        continue;
      }
      for (const auto& assignment : s->sets) {
        if (assignment.rfind(param + "=", 0) == 0) {
          throw Error(option->get_name() + " and --set " + assignment + " both set '" + param + "': give one",
                      kUsageExitCode);
        }
      }
      set_param(c.params, param + "=" + s->options.at(param));
    }
    YAML::Node topics(YAML::NodeType::Map);
    for (const auto& t : s->topics) {
      const auto eq = t.find('=');
      if (eq == std::string::npos) {
        throw Error("--topic expects key=name, got '" + t + "'", kUsageExitCode);
      }
      topics[t.substr(0, eq)] = t.substr(eq + 1);
    }
    runtime::apply_topic_overrides(topics, c.origin, spec.topics);
    spec.components.push_back(c);
    run_host(spec, s->run);
  });
}

}  // namespace

void register_run_commands(CLI::App& app) {
  auto options = std::make_shared<RunOptions>();
  auto host_path = std::make_shared<std::string>();
  auto list = std::make_shared<bool>(false);
  CLI::App* run = app.add_subcommand(
      "run", "Run drivers and components in one process from a host file (examples: " +
                 runtime::shipped_file_hint("hosts") + ")");
  run->add_option("host", *host_path, "Host file (YAML)");
  run->add_flag("--list", *list, "List the component types and exit");
  auto run_sets = std::make_shared<std::vector<std::string>>();
  run->add_option("--set", *run_sets,
                  "NAME.KEY=VALUE: change a parameter of the host's component NAME (as in its params "
                  "map; VALUE is YAML, e.g. pkf.declination_deg=3.4); repeatable")
      ->allow_extra_args(false)
      ->type_name("NAME.KEY=VALUE");
  add_run_options(run, *options);
  run->callback([options, host_path, list, run_sets] {
    if (*list) {
      for (const auto& [name, type] : runtime::ComponentRegistry::instance().types()) {
        std::printf("%-18s %s\n", name.c_str(), type.description.c_str());
      }
      return;
    }
    if (host_path->empty()) {
      throw Error("poise run needs a host file (e.g. " + runtime::shipped_file_hint("hosts/robot.yaml") + ")",
                  kUsageExitCode);
    }
    runtime::HostSpec host = runtime::load_host_file(*host_path);
    try {
      runtime::apply_component_sets(*run_sets, host);
    } catch (const std::invalid_argument& e) {
      throw Error(e.what(), kUsageExitCode);
    }
    run_host(host, *options);
  });

  // One `poise <component>` command per component type, to run it alone (one process each).
  for (const auto& [type_name, type] : runtime::ComponentRegistry::instance().types()) {
    if (type.standalone_command) {
      add_standalone_command(app, type_name, type);
    }
  }
}

}  // namespace poise::cli
