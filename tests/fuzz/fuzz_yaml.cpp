// Fuzz target for the YAML loaders (issue 19): arbitrary text as a YAML document through the
// shared loader (poise/core/yaml_params.h), the IMU driver configuration and the parameter files
// of the parallel KF, Gauss-Newton, the selective EKF, the altitude filter and the vehicle
// estimator (host files, intrinsics, tag maps and the camera configuration: fuzz_config).
// Invariant: each loader returns or throws a std::exception with a message; nothing else (crash,
// UB, a foreign exception) happens; an accepted document has at most two nodes per byte (aliases
// refused, issue 33; seeds alias_bomb.yaml, alias_cycle.yaml); accepted parameters are finite
// where the loaders promise it.
#include "fuzz_support.h"

#include "poise/altitude/altitude_filter.h"
#include "poise/core/yaml_params.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/imu/config.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/vehicle/vehicle_estimator.h"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

using poise::fuzz::expect_returns_or_refuses;

namespace {
/// Nodes in the tree below `n` (each alias expanded, as every reader walks it).
std::size_t tree_nodes(const YAML::Node& n, int depth) {
  if (depth > poise::kMaxYamlDepth + 1) std::abort();  // parse_yaml bounds the nesting
  std::size_t count = 1;
  if (n.IsMap()) {
    for (const auto& kv : n) count += tree_nodes(kv.first, depth + 1) + tree_nodes(kv.second, depth + 1);
  } else if (n.IsSequence()) {
    for (const auto& v : n) count += tree_nodes(v, depth + 1);
  }
  return count;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > 64 * 1024) return 0;  // yaml-cpp recursion on deep nesting is bounded by input size
  const std::string text(reinterpret_cast<const char*>(data), size);
  // Aliases (issue 33): refused before a node is built, so an accepted tree has at most two nodes
  // per byte of its text (an alias bomb: 9^9 nodes from 9 lines) and is no deeper than
  // kMaxYamlDepth.
  expect_returns_or_refuses([&] {
    const YAML::Node root = poise::parse_yaml(text, "fuzz");
    if (tree_nodes(root, 0) > 2 * text.size() + 2) std::abort();
  });
  expect_returns_or_refuses([&] { (void)poise::imu::parse_driver_config(text, "fuzz"); });
  const std::string path = poise::fuzz::as_file(text);
  if (path.empty()) return 0;
  expect_returns_or_refuses([&] {
    const poise::ParallelKfParams p = poise::load_parallel_kf_params(path);
    if (!std::isfinite(p.mag_norm_tol)) std::abort();
  });
  expect_returns_or_refuses([&] { (void)poise::load_gauss_newton_params(path); });
  expect_returns_or_refuses([&] { (void)poise::load_selective_ekf_params(path); });
  expect_returns_or_refuses([&] { (void)poise::load_altitude_params(path); });
  expect_returns_or_refuses([&] { (void)poise::load_vehicle_params(path); });
  return 0;
}
