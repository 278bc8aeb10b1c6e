// poise_imu_dev: a `poise` entry point with only the serial IMU commands, for fast local
// iteration on this driver (the product is the `poise` executable; this target is not built by
// default: `cmake --build build --target poise_imu_dev`).
#include <CLI/CLI.hpp>

#include <exception>
#include <iostream>

#include "poise/cli/common.h"
#include "poise/imu/imu_driver_node.h"

namespace poise::cli {
void register_imu_cli(CLI::App& app);
}

int main(int argc, char** argv) {
  CLI::App app{"poise (serial IMU commands only: development build)", "poise"};
  app.require_subcommand(1);
  poise::runtime::register_imu_driver(poise::runtime::ComponentRegistry::instance());
  poise::cli::register_imu_cli(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : poise::cli::kUsageExitCode;
  } catch (const poise::cli::ExitCode& e) {
    return e.code;
  } catch (const poise::cli::Error& e) {
    std::cerr << "poise: error: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::exception& e) {
    std::cerr << "poise: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
