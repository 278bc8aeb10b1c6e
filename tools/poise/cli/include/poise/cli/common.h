// Helpers shared by every `poise` subcommand module.
//
// Error conventions (STYLE.md habit 10):
//  - a usage error (unknown option, bad value) is reported by CLI11 with the usage text, exit 2;
//  - a setup or I/O failure throws poise::cli::Error (or any std::exception): main prints
//    "poise: error: <what>" and exits with the error's code (1 by default);
//  - a subcommand that completes returns normally (exit 0) or throws ExitCode for a specific code.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

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

/// Adds `--domain N` (0-232) to a subcommand. Without it, $POISE_DOMAIN (else 0) is read once the
/// command line is parsed, never while commands are registered: a bad value is an Error naming
/// the variable for that command, and `--help` works whatever the environment holds.
CLI::Option* add_domain_option(CLI::App* sub, int* domain);

// The one command grammar (docs/TOOLS.md "Command grammar"): every command spells a shared
// option the same way with the same meaning, through these helpers.

/// `-o,--output FILE`: the file a command writes ("Output file: <what>").
CLI::Option* add_output_file_option(CLI::App* sub, std::string* path, const std::string& what,
                                    bool required);
/// `--out-dir DIR`: the directory a command writes into ("Output directory: <what>").
CLI::Option* add_out_dir_option(CLI::App* sub, std::string* dir, const std::string& what, bool required);
/// `--dds-profile NAME`: the DDS participant profile (default $POISE_DDS_PROFILE, else
/// poise_default), "" = that default.
CLI::Option* add_dds_profile_option(CLI::App* sub, std::string* profile);
/// Runs `check` once `sub`'s command line is parsed (after --help was handled, before the
/// command's callback); throw CLI::ParseError or Error from it.
void on_parsed(CLI::App* sub, std::function<void()> check);

/// The old spelling `old_name` of `replacement` (an option of `sub` storing into `target`),
/// accepted for one release: hidden from --help, sets the same value and prints
/// "poise: note: '<cmd> OLD' is deprecated, use NEW (accepted until poise 0.2)" on stderr.
/// A required option with an old spelling is added with required = false, "(required)" in its
/// text, and checked through require_one_of() (CLI11's own requirement would refuse the alias).
void deprecation_note(const CLI::App* sub, const std::string& old_name, const std::string& new_name);
template <typename T>
CLI::Option* add_deprecated_alias(CLI::App* sub, const std::string& old_name, const std::string& new_name,
                                  T* target) {
  return sub
      ->add_option_function<T>(
          old_name,
          [sub, old_name, new_name, target](const T& value) {
            deprecation_note(sub, old_name, new_name);
            *target = value;
          },
          "deprecated spelling of " + new_name)
      ->group("");
}
/// Usage error (exit 2) "<name> is required" unless one of `options` was given.
void require_one_of(CLI::App* sub, std::vector<CLI::Option*> options);

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
