#include "poise/nodes/register.h"

#include <utility>

namespace poise::nodes {
namespace {
const std::vector<std::pair<std::string, StepFactory>>& step_table() {
  static const std::vector<std::pair<std::string, StepFactory>> table{
      {"parallel_kf", &make_parallel_kf_step},
      {"gauss_newton", &make_gauss_newton_step},
      {"selective_ekf", &make_selective_ekf_step},
      {"altitude", &make_altitude_step},
      {"vehicle", &make_vehicle_step}};
  return table;
}
}  // namespace

std::unique_ptr<EstimatorStep> make_estimator_step(const runtime::ComponentSpec& spec) {
  for (const auto& [type, make] : step_table()) {
    if (type == spec.type) {
      return make(spec);
    }
  }
  return nullptr;
}

const std::vector<std::string>& estimator_step_types() {
  static const std::vector<std::string> types = [] {
    std::vector<std::string> out;
    for (const auto& entry : step_table()) {
      out.push_back(entry.first);
    }
    return out;
  }();
  return types;
}
}  // namespace poise::nodes

namespace poise::runtime {
void register_estimator_nodes(ComponentRegistry& registry) {
  nodes::register_parallel_kf_node(registry);
  nodes::register_gauss_newton_node(registry);
  nodes::register_selective_ekf_node(registry);
  nodes::register_altitude_node(registry);
  nodes::register_vehicle_node(registry);
}
}  // namespace poise::runtime
