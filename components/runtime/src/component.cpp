#include "poise/runtime/component.h"

#include "poise/core/yaml_params.h"

#include <algorithm>

namespace poise::runtime {

ComponentRegistry& ComponentRegistry::instance() {
  static ComponentRegistry registry;
  return registry;
}

void ComponentRegistry::add(ComponentType type) {
  const std::string name = type.name;
  if (types_.count(name) != 0) {
    throw std::logic_error("component type '" + name + "' registered twice");
  }
  types_.emplace(name, std::move(type));
}

const ComponentType* ComponentRegistry::find(const std::string& name) const {
  const auto it = types_.find(name);
  return it == types_.end() ? nullptr : &it->second;
}

std::vector<std::string> ComponentRegistry::names() const {
  std::vector<std::string> out;
  out.reserve(types_.size());
  for (const auto& [name, type] : types_) {
    out.push_back(name);
  }
  return out;
}

void check_known_params(const ComponentSpec& spec, const std::vector<std::string>& known) {
  check_known_keys<ConfigError>(spec.params, known, spec.origin + ": " + spec.type);
}

}  // namespace poise::runtime
