// Helpers shared by every `poise` subcommand module.
//
// Error conventions (STYLE.md habit 10):
//  - a usage error (unknown option, bad value) is reported by CLI11 with the usage text, exit 2;
//  - a setup or I/O failure throws poise::cli::Error (or any std::exception): main prints
//    "poise: error: <what>" and exits with the error's code (1 by default);
//  - a subcommand that completes returns normally (exit 0) or throws ExitCode for a specific code.
#pragma once

#include <CLI/CLI.hpp>

#include <stdexcept>
#include <string>

namespace poise::cli {

/// A failure that the user can act on; `what()` says what to do.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message, int exit_code = 1)
      : std::runtime_error(message), exit_code_(exit_code) {}
  [[nodiscard]] int exit_code() const { return exit_code_; }

 private:
  int exit_code_;
};

/// Thrown by a subcommand to end with a specific exit code without an error message.
struct ExitCode {
  int code;
};

/// Exit code for usage errors (bad options).
inline constexpr int kUsageExitCode = 2;

/// The default DDS domain: $POISE_DOMAIN if set to a valid id (0-232), else 0.
/// Throws Error if POISE_DOMAIN is set but not a valid domain id.
int default_domain();

/// Adds `--domain N` (0-232, default from POISE_DOMAIN) to a subcommand.
CLI::Option* add_domain_option(CLI::App* sub, int* domain);

/// Returns the subcommand NAME of PARENT, creating it if needed (several modules may add commands
/// under the same group, e.g. `poise eval ...`, `poise bench ...`, `poise sim ...`).
CLI::App* subcommand_group(CLI::App& parent, const std::string& name,
                           const std::string& description);

/// True once SIGINT or SIGTERM has been received (after install_stop_handlers()).
bool stop_requested();
/// Installs SIGINT/SIGTERM handlers that set stop_requested(); idempotent.
void install_stop_handlers();
/// Requests a stop from code (tests, --duration timers).
void request_stop();

}  // namespace poise::cli
