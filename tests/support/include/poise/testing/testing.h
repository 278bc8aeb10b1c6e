// Test helpers shared by every poise test. Keep tests free of copy-pasted helpers: add them here.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace poise::testing {

/// An exclusive DDS domain id for the lifetime of this object, across processes: a lock file per
/// domain under $TMPDIR/poise-test-domains (flock), so parallel ctest runs never cross-talk.
class DomainLease {
 public:
  DomainLease();
  ~DomainLease();
  DomainLease(const DomainLease&) = delete;
  DomainLease& operator=(const DomainLease&) = delete;
  [[nodiscard]] int id() const { return id_; }

 private:
  int id_ = -1;
  int fd_ = -1;
};

/// The shared data directory (BROAD recordings, papers) or nullopt when it is not present.
std::optional<std::string> shared_dir();

/// Path of a built executable (e.g. "poise").
std::string bin(const std::string& name);

/// Path inside the source tree.
std::string source_path(const std::string& relative);

/// The whole content of a file ("" when it cannot be read).
std::string read_file(const std::string& path);

/// A child process with stdout+stderr captured to a file; killed (SIGKILL) on destruction.
class Child {
 public:
  explicit Child(const std::vector<std::string>& argv, const std::vector<std::string>& env = {});
  ~Child();
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  /// Waits up to `timeout`; returns the exit code (128+signal when killed by a signal) or nullopt.
  std::optional<int> wait_for(std::chrono::milliseconds timeout);
  /// Sends a signal (e.g. SIGINT, SIGKILL).
  void signal(int sig);
  [[nodiscard]] int pid() const { return pid_; }
  /// Everything the child wrote so far (stdout and stderr, interleaved).
  [[nodiscard]] std::string output() const;

 private:
  int pid_ = -1;
  std::optional<int> status_;
  std::string log_path_;
};

/// Runs a command to completion (bounded by `timeout`), returning {exit code, output}.
/// The exit code is -1 when the command timed out (it is then killed).
struct RunResult {
  int exit_code;
  std::string output;
};
RunResult run(const std::vector<std::string>& argv, std::chrono::milliseconds timeout,
              const std::vector<std::string>& env = {});

/// Polls `predicate` every 10 ms until it is true or `timeout` elapses; returns the last value.
void sleep_ms(int ms);

/// True when a test that cannot run must fail instead of skipping: the environment has CI=true
/// (what CI services set) or POISE_REQUIRE_ALL=1.
bool require_all();

template <typename Predicate>
bool wait_until(Predicate predicate, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (predicate()) {
      return true;
    }
    sleep_ms(10);
  }
  return predicate();
}

}  // namespace poise::testing

/// Skips the current test with `reason` (a std::string or string literal) because something it
/// needs is missing - or FAILS it when every test must run (require_all(): CI=true or
/// POISE_REQUIRE_ALL=1), so CI can never go green by skipping. Every skip goes through this.
#define POISE_SKIP(reason)                                                                 \
  do {                                                                                     \
    if (::poise::testing::require_all()) {                                                 \
      FAIL() << "cannot run and skipping is not allowed (CI=true / POISE_REQUIRE_ALL=1): " \
             << (reason);                                                                  \
    }                                                                                      \
    GTEST_SKIP() << (reason);                                                              \
  } while (false)

/// Skips (or, under require_all(), fails) the current test when the shared data directory is
/// missing.
#define POISE_REQUIRE_SHARED_DIR(var)                                                      \
  const auto var##_opt = ::poise::testing::shared_dir();                                   \
  if (!var##_opt) {                                                                        \
    POISE_SKIP("shared data directory not found (set POISE_SHARED_DIR or place "           \
               "shared/ beside the clone); a user's clone does not have it");              \
  }                                                                                        \
  const std::string var = *var##_opt
