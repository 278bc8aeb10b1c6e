// The single `poise` entry point. Subcommands come from modules registered in CMake with
// poise_add_cli_module(); see components/cli/include/poise/cli/common.h for the conventions.
#include "poise/cli/common.h"

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdlib>
#include <exception>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

namespace poise::runtime {
void register_all_components();
}
namespace poise::cli {
void register_all_modules(CLI::App& app);
}

namespace {

/// CLI11 reports "A subcommand is required" for `poise nosuchcmd` and `poise eval --bogus`: name
/// what was not understood instead, from the deepest subcommand that was recognised.
std::string explain_unparsed(CLI::App& app) {
  CLI::App* at = &app;
  std::string path = app.get_name();
  for (;;) {
    const std::vector<CLI::App*> parsed = at->get_subcommands();
    if (parsed.empty()) {
      break;
    }
    at = parsed.front();
    path += " " + at->get_name();
  }
  const std::vector<std::string> rest = at->remaining(true);
  if (rest.empty()) {
    return {};
  }
  if (!rest.front().empty() && rest.front()[0] == '-') {
    return "'" + path + "': unknown option '" + rest.front() + "' (see " + path + " --help)";
  }
  std::string known;
  for (const CLI::App* sub : at->get_subcommands(std::function<bool(CLI::App*)>([](CLI::App*) { return true; }))) {
    known += (known.empty() ? "" : ", ") + sub->get_name();
  }
  return "'" + path + "': unknown subcommand '" + rest.front() + "'" + (known.empty() ? "" : " (known: " + known + ")");
}

/// Every floating-point option of every subcommand refuses NaN and infinities (`--duration nan`
/// would run forever, `--rate inf` divide by it): one validator added after registration.
void refuse_non_finite_numbers(CLI::App& app) {
  const CLI::Validator finite(
      [](std::string& value) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(value.c_str(), &end);
        if (end != value.c_str() && *end == '\0' && !std::isfinite(v)) {
          return "'" + value + "' is not a finite number";
        }
        return {};
      },
      "FINITE");
  for (CLI::Option* opt : app.get_options()) {
    if (opt->get_type_name().find("FLOAT") != std::string::npos) {
      opt->check(finite);
    }
  }
  for (CLI::App* sub : app.get_subcommands(std::function<bool(CLI::App*)>([](CLI::App*) { return true; }))) {
    refuse_non_finite_numbers(*sub);
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"poise: real-time attitude and pose estimation over DDS", "poise"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "poise 0.1.0");
  try {
    poise::runtime::register_all_components();
    poise::cli::register_all_modules(app);
    refuse_non_finite_numbers(app);
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
  } catch (const CLI::RequiredError& e) {
    const std::string unparsed = explain_unparsed(app);
    if (unparsed.empty()) {
      app.exit(e);
    } else {
      std::cerr << "poise: error: " << unparsed << "\n";
    }
    return poise::cli::kUsageExitCode;
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
