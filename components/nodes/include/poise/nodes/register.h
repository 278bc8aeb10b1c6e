// Registration functions of the estimator nodes (called through poise_add_component_module).
#pragma once

#include "poise/runtime/component.h"

namespace poise::nodes {
void register_parallel_kf_node(runtime::ComponentRegistry& registry);
void register_gauss_newton_node(runtime::ComponentRegistry& registry);
void register_selective_ekf_node(runtime::ComponentRegistry& registry);
void register_altitude_node(runtime::ComponentRegistry& registry);
void register_vehicle_node(runtime::ComponentRegistry& registry);
}  // namespace poise::nodes

namespace poise::runtime {
/// Registers every estimator node built into this library set.
void register_estimator_nodes(ComponentRegistry& registry);
}  // namespace poise::runtime
