#include "poise/runtime/host.h"

#include "poise/core/yaml_params.h"
#include "poise/runtime/shipped.h"

#include <algorithm>
#include <filesystem>
#include <set>
#include <utility>
#include <vector>
#include <stdexcept>

namespace poise::runtime {
namespace fs = std::filesystem;

namespace {
/// Where the relative paths of a host file are looked up.
struct PathBases {
  std::string host_dir;           ///< the host file's directory
  std::string shipped_hosts_dir;  ///< the shipped host files' directory ("" when none)
};

/// A path named in a host file (`key` of `where`): an absolute one as it is; a relative one beside
/// the host file, else beside the shipped host files, the first that exists (a shipped host file
/// copied to /etc/poise still finds the shipped filter and driver files its `../filters/...`
/// name); found in neither place, a ConfigError naming every path tried.
std::string resolve(const PathBases& bases, const std::string& path, const std::string& where,
                    const std::string& key) {
  if (path.empty() || fs::path(path).is_absolute()) {
    return path;
  }
  const std::string beside = (fs::path(bases.host_dir) / path).lexically_normal().string();
  std::error_code ec;
  if (fs::exists(beside, ec)) {
    return beside;
  }
  std::string tried = " at " + beside + " (beside the host file";
  const std::string shipped = bases.shipped_hosts_dir.empty()
                                  ? std::string()
                                  : (fs::path(bases.shipped_hosts_dir) / path).lexically_normal().string();
  if (shipped.empty()) {
    tried += "; no shipped configuration was found beside this executable)";
  } else if (shipped == beside) {
    tried += ", one of the shipped host files)";
  } else if (fs::exists(shipped, ec)) {
    return shipped;
  } else {
    tried += ") nor at " + shipped + " (beside the shipped host files)";
  }
  throw ConfigError(where + ": " + key + " '" + path + "' not found" + tried +
                    "; give an absolute path or one relative to the host file");
}

/// Copies `overlay`'s entries onto `base` (a fresh map), key by key.
YAML::Node merge(const YAML::Node& base, const YAML::Node& overlay) {
  YAML::Node out(YAML::NodeType::Map);
  for (const auto* node : {&base, &overlay}) {
    if (*node && node->IsMap()) {
      for (const auto& entry : *node) {
        out[entry.first.as<std::string>()] = YAML::Clone(entry.second);
      }
    }
  }
  return out;
}
}  // namespace

YAML::Node load_param_file(const std::string& path) {
  if (!fs::exists(path)) {
    throw ConfigError("parameter file '" + path + "' does not exist");
  }
  const YAML::Node node = load_yaml_file<ConfigError>(path, "parameter file");
  if (node.IsNull()) {
    return YAML::Node(YAML::NodeType::Map);
  }
  if (!node.IsMap()) {
    throw ConfigError("parameter file '" + path + "' must be a YAML map of parameters");
  }
  return node;
}

void apply_topic_overrides(const YAML::Node& map, const std::string& origin, dds::TopicNames& names) {
  if (!map) {
    return;
  }
  if (!map.IsMap()) {
    throw ConfigError(origin + ": 'topics' must be a map of name overrides");
  }
  const std::vector<std::pair<std::string, std::string*>> fields{
      {"imu", &names.imu},
      {"imu_info", &names.imu_info},
      {"tag_detections", &names.tag_detections},
      {"vision_pose", &names.vision_pose},
      {"attitude_prefix", &names.attitude_prefix},
      {"pose_prefix", &names.pose_prefix},
      {"altitude", &names.altitude},
      {"vehicle_input", &names.vehicle_input},
      {"diagnostics", &names.diagnostics},
  };
  std::vector<std::string> known;
  for (const auto& f : fields) {
    known.push_back(f.first);
  }
  check_known_keys<ConfigError>(map, known, origin, "topics.");
  for (const auto& entry : map) {
    const auto key = yaml_key_text(entry.first);
    const auto it = std::find_if(fields.begin(), fields.end(), [&key](const auto& f) { return f.first == key; });
    if (!entry.second.IsScalar()) {
      throw ConfigError(origin + ": topics." + key + " must be a topic name (a string)");
    }
    const auto value = entry.second.Scalar();
    if (value.empty()) {
      throw ConfigError(origin + ": topic '" + key + "' must not be empty");
    }
    *it->second = value;
  }
}

namespace {
/// One entry of a host file's `components` list (YAML type errors propagate to the caller).
ComponentSpec parse_component(const YAML::Node& entry, const std::string& origin, const std::string& at,
                              const PathBases& bases) {
  const std::string where = origin + ": " + at;
  if (!entry.IsMap() || !entry["type"]) {
    throw ConfigError(where + ": each component needs a 'type'");
  }
  check_known_keys<ConfigError>(entry, {"type", "name", "config", "params"}, origin, at + ".");
  ComponentSpec c;
  c.type = entry["type"].as<std::string>();
  c.name = entry["name"] ? entry["name"].as<std::string>() : c.type;
  c.origin = where + " (" + c.name + ")";
  YAML::Node from_file;
  if (entry["config"]) {
    from_file = load_param_file(resolve(bases, entry["config"].as<std::string>(), where, "config"));
  }
  if (entry["params"] && !entry["params"].IsMap()) {
    throw ConfigError(where + ": 'params' must be a map");
  }
  c.params = merge(from_file, entry["params"]);
  // Parameters named *_file are paths, resolved as `config` is.
  for (auto param : c.params) {
    const auto key = param.first.as<std::string>();
    if (key.size() > 5 && key.compare(key.size() - 5, 5, "_file") == 0 && param.second.IsScalar()) {
      c.params[key] = resolve(bases, param.second.as<std::string>(), c.origin, "params." + key);
    }
  }
  return c;
}
}  // namespace

HostSpec parse_host(const YAML::Node& root, const std::string& origin, const std::string& base_dir,
                    const std::string& shipped_hosts) {
  const PathBases bases{base_dir, shipped_hosts};
  if (!root || !root.IsMap()) {
    throw ConfigError(origin + ": a host file is a YAML map with a 'components' list");
  }
  check_known_keys<ConfigError>(root, {"domain", "participant_profile", "qos_file", "topics", "realtime", "components"},
                                origin);
  HostSpec spec;
  spec.path = origin;
  try {
    if (root["domain"]) {
      const int domain = root["domain"].as<int>();
      if (domain < 0 || domain > 232) {
        throw ConfigError(origin + ": domain must be 0-232");
      }
      spec.domain = domain;
    }
    if (root["participant_profile"]) {
      spec.participant_profile = root["participant_profile"].as<std::string>();
    }
    if (root["qos_file"]) {
      spec.qos_file = resolve(bases, root["qos_file"].as<std::string>(), origin, "qos_file");
    }
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ": " + e.what());
  }
  apply_topic_overrides(root["topics"], origin, spec.topics);
  spec.realtime = parse_realtime(root["realtime"], origin);

  const YAML::Node list = root["components"];
  if (!list || !list.IsSequence() || list.size() == 0) {
    throw ConfigError(origin + ": 'components' must be a non-empty list");
  }
  std::set<std::string> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string at = "components[" + std::to_string(i) + "]";
    const std::string where = origin + ": " + at;
    try {
      spec.components.push_back(parse_component(list[i], origin, at, bases));
    } catch (const YAML::Exception& e) {
      throw ConfigError(where + ": " + e.msg + " (type, name and config are strings, params a map)");
    }
    const ComponentSpec& c = spec.components.back();
    if (!names.insert(c.name).second) {
      throw ConfigError(where + ": two components are named '" + c.name + "' (names must be unique)");
    }
  }
  return spec;
}

std::string shipped_hosts_dir() {
  const std::string dir = shipped_config_dir();
  return dir.empty() ? dir : (fs::path(dir) / "hosts").string();
}

HostSpec load_host_file(const std::string& path) {
  if (!fs::exists(path)) {
    throw ConfigError("host file '" + path + "' does not exist");
  }
  const YAML::Node root = load_yaml_file<ConfigError>(path, "host file");
  return parse_host(root, path, fs::path(path).parent_path().string());
}

Host::Host(const HostSpec& spec, int domain) {
  const auto& registry = ComponentRegistry::instance();
  for (const auto& c : spec.components) {  // fail before creating any DDS entity
    if (registry.find(c.type) == nullptr) {
      std::string list;
      for (const auto& n : registry.names()) {
        list += (list.empty() ? "" : ", ") + n;
      }
      throw ConfigError(c.origin + ": unknown component type '" + c.type + "' (known: " + list + ")");
    }
    try {
      (void)dds::checked_sensor_id(c.name, c.origin);
    } catch (const std::invalid_argument& e) {
      throw ConfigError(e.what());
    }
  }
  dds::ParticipantOptions options;
  options.domain = domain;
  options.profile = spec.participant_profile;
  options.qos_file = spec.qos_file;
  options.name = "poise:" + (spec.components.size() == 1 ? spec.components.front().name
                                                          : std::string("host"));
  participant_ = std::make_unique<dds::Participant>(options);
  context_ = std::make_unique<HostContext>(HostContext{*participant_, spec.topics, options});
  for (const auto& c : spec.components) {
    components_.push_back(registry.find(c.type)->create(c, *context_));
    names_.push_back(c.name);
  }
}

Host::~Host() {
  stop();
  // Destroy in reverse order of creation (later components may read earlier ones' topics).
  while (!components_.empty()) {
    components_.pop_back();
  }
}

void Host::start() {
  for (auto& c : components_) {
    c->start();
  }
  started_ = true;
}

void Host::stop() {
  if (!started_) {
    return;
  }
  for (auto it = components_.rbegin(); it != components_.rend(); ++it) {
    (*it)->stop();
  }
  started_ = false;
}

std::vector<std::string> Host::status() const {
  std::vector<std::string> lines;
  for (std::size_t i = 0; i < components_.size(); ++i) {
    const std::string s = components_[i]->status();
    if (!s.empty()) {
      lines.push_back(names_[i] + ": " + s);
    }
  }
  return lines;
}

std::vector<ComponentOutput> Host::produced() const {
  std::vector<ComponentOutput> out;
  out.reserve(components_.size());
  for (std::size_t i = 0; i < components_.size(); ++i) {
    out.push_back({names_[i], components_[i]->produced()});
  }
  return out;
}

void apply_component_sets(const std::vector<std::string>& sets, HostSpec& host) {
  for (const std::string& set : sets) {
    const size_t eq = set.find('=');
    const size_t dot = set.find('.');
    if (eq == std::string::npos || dot == std::string::npos || dot == 0 || dot > eq || eq < dot + 2) {
      throw std::invalid_argument("--set " + set + ": expected NAME.key=value (NAME: a component of the host file)");
    }
    const std::string name = set.substr(0, dot);
    const std::string key = set.substr(dot + 1, eq - dot - 1);
    YAML::Node value;
    try {
      value = parse_yaml(set.substr(eq + 1), "--set " + set);
    } catch (const std::runtime_error& e) {
      throw std::invalid_argument("--set " + set + ": the value is not YAML: " + e.what());
    }
    bool found = false;
    std::string names;
    for (ComponentSpec& c : host.components) {
      names += (names.empty() ? "" : ", ") + c.name;
      if (c.name == name) {
        if (!c.params || !c.params.IsMap()) {
          c.params = YAML::Node(YAML::NodeType::Map);
        }
        c.params[key] = value;
        c.origin += " (with --set " + set + ")";
        found = true;
      }
    }
    if (!found) {
      throw std::invalid_argument("--set " + set + ": no component named '" + name + "' in the host file (" +
                                  names + ")");
    }
  }
}

}  // namespace poise::runtime
