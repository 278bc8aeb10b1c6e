#include "poise/nodes/register.h"

namespace poise::runtime {
void register_estimator_nodes(ComponentRegistry& registry) {
  nodes::register_parallel_kf_node(registry);
  nodes::register_gauss_newton_node(registry);
  nodes::register_selective_ekf_node(registry);
  nodes::register_altitude_node(registry);
  nodes::register_vehicle_node(registry);
}
}  // namespace poise::runtime
