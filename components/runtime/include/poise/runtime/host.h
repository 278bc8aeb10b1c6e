// Host files (`poise run HOST.yaml`): which components run in one process, their parameters,
// topic names, domain and QoS.
//
//   domain: 0                      # optional; --domain overrides; default $POISE_DOMAIN or 0
//   participant_profile: poise_default   # optional (poise_default | poise_udp | poise_loopback)
//   qos_file: ../qos/poise_profiles.xml  # optional; relative paths are relative to this file
//   topics: {imu: imu, attitude_prefix: attitude/}   # optional overrides of the default names
//   realtime: {priority: 80, cpus: [2, 3], lock_memory: true}   # optional (realtime.h)
//   components:
//     - type: parallel_kf          # a registered component type (`poise run --list`)
//       name: pkf                  # optional instance name (default: type)
//       config: ../filters/parallel_kf.yaml   # optional parameter file (YAML map)
//       params: {preset: default}  # optional inline parameters, override the config file
//   Parameters whose name ends in `_file` are paths. A relative path (`config`, `qos_file`,
//   `*_file`) is looked up beside this file, else beside the shipped host files
//   (<prefix>/share/poise/hosts, poise/runtime/shipped.h), so a shipped host file copied to
//   /etc/poise still finds the shipped filter and driver files; found nowhere, an error names
//   every path tried.
#pragma once

#include "poise/runtime/component.h"
#include "poise/runtime/realtime.h"

#include <atomic>
#include <optional>
#include <string>
#include <vector>

namespace poise::runtime {

struct HostSpec {
  std::optional<int> domain;
  std::string participant_profile;
  std::string qos_file;
  dds::TopicNames topics;
  RealtimeSettings realtime;
  std::vector<ComponentSpec> components;
  std::string path;  ///< the host file
};

/// Parses and validates a host file; throws ConfigError with the file, the key and what to do.
HostSpec load_host_file(const std::string& path);
/// The shipped host files' directory (<shipped_config_dir()>/hosts), "" when there is none.
std::string shipped_hosts_dir();

/// The same from YAML text: relative paths are looked up in `base_dir` (the host file's
/// directory), then in `shipped_hosts` ("" for nowhere else).
HostSpec parse_host(const YAML::Node& root, const std::string& origin, const std::string& base_dir,
                    const std::string& shipped_hosts = shipped_hosts_dir());

/// Applies a `topics:` map onto names; throws ConfigError on unknown keys.
void apply_topic_overrides(const YAML::Node& map, const std::string& origin, dds::TopicNames& names);

/// Applies `--set NAME.key=VALUE` assignments (VALUE read as YAML: numbers, lists, maps,
/// strings) to the params of the host's component NAME (`poise run`, `poise process`). Throws
/// std::invalid_argument naming the assignment when it is not NAME.key=VALUE, VALUE is not YAML
/// or no component is called NAME (the message lists them).
void apply_component_sets(const std::vector<std::string>& sets, HostSpec& host);

/// Loads a YAML parameter file as a map (ConfigError if missing or not a map).
YAML::Node load_param_file(const std::string& path);

/// What one component has produced so far (Component::produced()), by instance name.
struct ComponentOutput {
  std::string name;
  std::optional<uint64_t> produced;
};

/// Runs components in one process until `stop` becomes true (or a component fails).
class Host {
 public:
  Host(const HostSpec& spec, int domain);
  ~Host();
  Host(const Host&) = delete;
  Host& operator=(const Host&) = delete;

  void start();
  void stop();
  /// One status line per component.
  [[nodiscard]] std::vector<std::string> status() const;
  /// Component::produced() of every component, in host-file order.
  [[nodiscard]] std::vector<ComponentOutput> produced() const;
  /// Number of components.
  [[nodiscard]] std::size_t size() const { return components_.size(); }
  [[nodiscard]] dds::Participant& participant() { return *participant_; }

 private:
  std::unique_ptr<dds::Participant> participant_;
  std::unique_ptr<HostContext> context_;
  std::vector<std::string> names_;
  std::vector<std::unique_ptr<Component>> components_;
  bool started_ = false;
};

}  // namespace poise::runtime
