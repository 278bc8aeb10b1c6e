// The single `poise` entry point. Subcommands come from modules registered in CMake with
// poise_add_cli_module(); see components/cli/include/poise/cli/common.h for the conventions.
#include "poise/cli/common.h"

#include <CLI/CLI.hpp>

#include <exception>
#include <iostream>

namespace poise::runtime {
void register_all_components();
}
namespace poise::cli {
void register_all_modules(CLI::App& app);
}

int main(int argc, char** argv) {
  CLI::App app{"poise: real-time attitude and pose estimation over DDS", "poise"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "poise 0.1.0");
  try {
    poise::runtime::register_all_components();
    poise::cli::register_all_modules(app);
  } catch (const std::exception& e) {
    std::cerr << "poise: internal error while registering commands: " << e.what() << "\n";
    return 1;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);  // prints the message and the usage hint
    return poise::cli::kUsageExitCode;
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
