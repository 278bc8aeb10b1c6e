// Fuzz target for the YAML loaders (issue 19): arbitrary text as a YAML document through the
// shared loader (poise/core/yaml_params.h), the IMU driver configuration and the parameter files
// of the parallel KF, Gauss-Newton and the selective EKF. Invariant: each loader returns or
// throws a std::exception with a message; nothing else (crash, UB, a foreign exception) happens,
// and accepted parameters are finite where the loaders promise it.
#include "poise/core/yaml_params.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/imu/config.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/selective_ekf/selective_ekf.h"

#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

template <typename F>
void expect_returns_or_refuses(F f) {
  try {
    f();
  } catch (const std::exception& e) {
    if (e.what() == nullptr || e.what()[0] == '\0') std::abort();  // a refusal says why
  } catch (...) {
    std::abort();
  }
}

std::string temp_path() {
  static const std::string path = "/tmp/poise_fuzz_yaml_" + std::to_string(::getpid()) + ".yaml";
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > 64 * 1024) return 0;  // yaml-cpp recursion on deep nesting is bounded by input size
  const std::string text(reinterpret_cast<const char*>(data), size);
  expect_returns_or_refuses([&] { (void)poise::parse_yaml(text, "fuzz"); });
  expect_returns_or_refuses([&] { (void)poise::imu::parse_driver_config(text, "fuzz"); });
  if (std::FILE* f = std::fopen(temp_path().c_str(), "wb")) {
    std::fwrite(text.data(), 1, text.size(), f);
    std::fclose(f);
    expect_returns_or_refuses([&] {
      const poise::ParallelKfParams p = poise::load_parallel_kf_params(temp_path());
      if (!std::isfinite(p.mag_norm_tol)) std::abort();
    });
    expect_returns_or_refuses([&] { (void)poise::load_gauss_newton_params(temp_path()); });
    expect_returns_or_refuses([&] { (void)poise::load_selective_ekf_params(temp_path()); });
  }
  return 0;
}
