// Fuzz target for the YAML loaders (issue 19): arbitrary text as a YAML document through the
// shared loader (poise/core/yaml_params.h), the IMU driver configuration and the parameter files
// of the parallel KF, Gauss-Newton, the selective EKF, the altitude filter and the vehicle
// estimator (host files, intrinsics, tag maps and the camera configuration: fuzz_config).
// Invariant: each loader returns or throws a std::exception with a message; nothing else (crash,
// UB, a foreign exception) happens, and accepted parameters are finite where the loaders promise it.
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

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > 64 * 1024) return 0;  // yaml-cpp recursion on deep nesting is bounded by input size
  const std::string text(reinterpret_cast<const char*>(data), size);
  expect_returns_or_refuses([&] { (void)poise::parse_yaml(text, "fuzz"); });
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
