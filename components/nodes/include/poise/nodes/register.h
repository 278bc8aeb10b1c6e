// Registration functions of the estimator nodes (called through poise_add_component_module), and
// the steps behind them (poise/nodes/estimator_step.h) for running a component without DDS.
#pragma once

#include "poise/nodes/estimator_step.h"
#include "poise/runtime/component.h"

#include <memory>
#include <vector>

namespace poise::nodes {
void register_parallel_kf_node(runtime::ComponentRegistry& registry);
void register_gauss_newton_node(runtime::ComponentRegistry& registry);
void register_selective_ekf_node(runtime::ComponentRegistry& registry);
void register_altitude_node(runtime::ComponentRegistry& registry);
void register_vehicle_node(runtime::ComponentRegistry& registry);

/// The step of each estimator component (what its live node runs), from its host-file spec;
/// throws runtime::ConfigError on bad parameters, exactly as the node does.
std::unique_ptr<EstimatorStep> make_parallel_kf_step(const runtime::ComponentSpec& spec);
std::unique_ptr<EstimatorStep> make_gauss_newton_step(const runtime::ComponentSpec& spec);
std::unique_ptr<EstimatorStep> make_selective_ekf_step(const runtime::ComponentSpec& spec);
std::unique_ptr<EstimatorStep> make_altitude_step(const runtime::ComponentSpec& spec);
std::unique_ptr<EstimatorStep> make_vehicle_step(const runtime::ComponentSpec& spec);

/// The step of an estimator component of any type above; null when `spec.type` is not an
/// estimator (a driver, a simulator). Throws runtime::ConfigError on bad parameters.
std::unique_ptr<EstimatorStep> make_estimator_step(const runtime::ComponentSpec& spec);
/// The component types make_estimator_step() knows.
const std::vector<std::string>& estimator_step_types();
}  // namespace poise::nodes

namespace poise::runtime {
/// Registers every estimator node built into this library set.
void register_estimator_nodes(ComponentRegistry& registry);
}  // namespace poise::runtime
