// A parallel_kf component spec with the given host-file params (YAML flow map), for the node
// tests that read NodeParams.
#pragma once

#include "poise/runtime/component.h"

#include <yaml-cpp/yaml.h>

#include <string>

namespace poise::nodes {

inline runtime::ComponentSpec spec_with(const std::string& params) {
  runtime::ComponentSpec spec;
  spec.type = "parallel_kf";
  spec.name = "pkf";
  spec.origin = "test.yaml";
  spec.params = YAML::Load(params);
  return spec;
}

}  // namespace poise::nodes
