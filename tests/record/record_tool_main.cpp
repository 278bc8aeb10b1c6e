// `poise` with only the record commands (same exit-code conventions as tools/poise/cli), so the
// recorder tests do not depend on every other CLI module being built.
#include "poise/cli/common.h"

#include <CLI/CLI.hpp>

#include <iostream>

namespace poise::cli {
void add_record_commands(CLI::App& app);
}

int main(int argc, char** argv) {
  CLI::App app{"poise (record commands only; test build)", "poise"};
  app.require_subcommand(1);
  poise::cli::add_record_commands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return poise::cli::kUsageExitCode;
  } catch (const poise::cli::ExitCode& e) {
    return e.code;
  } catch (const std::exception& e) {
    std::cerr << "poise: error: " << e.what() << "\n";
    const auto* error = dynamic_cast<const poise::cli::Error*>(&e);
    return error != nullptr ? error->exit_code() : 1;
  }
  return 0;
}
