// Components: DDS nodes around estimators and drivers, composable in one host process
// (`poise run HOST.yaml`) or run alone (`poise <component> ...`, one process per component).
//
// A component type registers a factory in the ComponentRegistry (from a module listed in CMake
// with poise_add_component_module). The host owns one DDS participant shared by its components.
#pragma once

#include "poise/dds/participant.h"
#include "poise/dds/topics.h"

#include <yaml-cpp/yaml.h>

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace poise::runtime {

/// A configuration error (host file, component parameters); the message says what to fix.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// One component instance as described by a host file or the command line.
struct ComponentSpec {
  std::string type;     ///< registry key, e.g. "parallel_kf"
  std::string name;     ///< instance name: the sensor_id of what it publishes (default: type)
  YAML::Node params;    ///< parameters: the `config` file's content merged with inline `params`
  std::string origin;   ///< where the spec came from, for error messages
};

/// What a component gets from its host.
struct HostContext {
  dds::Participant& participant;
  dds::TopicNames topics;
  /// What the host's participant was made from (domain, profile, QoS file), for components that
  /// need a participant of their own on the same domain (e.g. an observer of every topic).
  dds::ParticipantOptions participant_options = {};
};

/// A running component. Construction creates its DDS entities (and throws on failure);
/// start() begins work; stop() ends it (idempotent); the destructor releases everything.
class Component {
 public:
  virtual ~Component() = default;
  virtual void start() {}
  virtual void stop() {}
  /// One line of live status (rates, counts) for the host's periodic print; empty for none.
  [[nodiscard]] virtual std::string status() const { return {}; }
  /// How much the component has produced so far (samples, estimates, frames, forwarded messages):
  /// a count that only grows. The service watchdog (service.h) is fed only while every component
  /// that has one keeps producing. nullopt: the component produces on demand only (a server
  /// waiting for clients) and is not watched.
  [[nodiscard]] virtual std::optional<uint64_t> produced() const { return std::nullopt; }
};

using ComponentFactory =
    std::function<std::unique_ptr<Component>(const ComponentSpec& spec, HostContext& host)>;

struct ComponentType {
  std::string name;         ///< registry key and host-file `type`
  std::string description;  ///< one line for --help
  ComponentFactory create;
  /// Generate `poise <name with dashes>` to run it alone. False for drivers that have their own
  /// dedicated command (e.g. `poise imu`).
  bool standalone_command = true;
  /// Name of that command ("": the type name with dashes, e.g. `poise parallel-kf`).
  std::string command{};
  /// Options of that command that set one parameter each: `poise foxglove --port 9000` is
  /// `--set port=9000` (the value read as YAML, checked by the component like a host file's).
  struct CommandOption {
    std::string flag;       ///< e.g. "--port"
    std::string key;        ///< the parameter it sets, e.g. "port"
    std::string type_name;  ///< shown in --help, e.g. "INT"
    std::string help;
  };
  std::vector<CommandOption> command_options{};
};

class ComponentRegistry {
 public:
  static ComponentRegistry& instance();
  void add(ComponentType type);
  [[nodiscard]] const ComponentType* find(const std::string& name) const;
  [[nodiscard]] std::vector<std::string> names() const;
  [[nodiscard]] const std::map<std::string, ComponentType>& types() const { return types_; }

 private:
  std::map<std::string, ComponentType> types_;
};

/// Reads a typed parameter with a default; throws ConfigError naming the key and the component
/// when the value has the wrong type or none (`key:` / `key: ~`: never silently the default).
template <typename T>
T param(const ComponentSpec& spec, const std::string& key, const T& fallback) {
  if (!spec.params || !spec.params[key]) {
    return fallback;
  }
  if (spec.params[key].IsNull()) {
    throw ConfigError(spec.origin + ": parameter '" + key + "' of component '" + spec.name +
                      "' has no value (empty or ~): give one, or leave the key out for the default");
  }
  try {
    return spec.params[key].as<T>();
  } catch (const YAML::Exception&) {
    throw ConfigError(spec.origin + ": parameter '" + key + "' of component '" + spec.name +
                      "' has the wrong type");
  }
}

/// Rejects parameters a component does not know (catches typos instead of ignoring them): the one
/// unknown-key message (poise/core/yaml_params.h), "<origin>: <type>: unknown key '<key>' (known:
/// ...)", as ConfigError.
void check_known_params(const ComponentSpec& spec, const std::vector<std::string>& known);

}  // namespace poise::runtime
