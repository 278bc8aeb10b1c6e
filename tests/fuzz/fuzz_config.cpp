// Fuzz target for the remaining configuration loaders (issue 19): host files
// (poise::runtime::parse_host), camera intrinsics (OpenCV calibration YAML / ROS camera_info
// forms), tag maps and the camera configuration. Invariant: each loader returns or throws a
// std::exception with a message (ConfigError naming the file and key); no crash, no UB, no foreign
// exception.
#include "fuzz_support.h"

#include "poise/camera/intrinsics.h"
#include "poise/camera/pipeline.h"
#include "poise/camera/tag_map.h"
#include "poise/core/yaml_params.h"
#include "poise/runtime/host.h"

#include <cstddef>
#include <cstdint>
#include <string>

using poise::fuzz::expect_returns_or_refuses;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > 64 * 1024) return 0;  // yaml-cpp recursion on deep nesting is bounded by input size
  const std::string text(reinterpret_cast<const char*>(data), size);
  expect_returns_or_refuses([&] {
    (void)poise::runtime::parse_host(poise::parse_yaml(text, "fuzz"), "fuzz", "/nonexistent");
  });
  expect_returns_or_refuses([&] { (void)poise::camera::parse_intrinsics(text, "fuzz"); });
  expect_returns_or_refuses([&] { (void)poise::camera::parse_tag_map(text, "fuzz"); });
  expect_returns_or_refuses([&] { (void)poise::camera::parse_camera_config(text, "fuzz"); });
  return 0;
}
