#include "poise/testing/testing.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace poise::testing {
namespace {
constexpr int kFirstTestDomain = 100;  // leave low ids for users' live systems
constexpr int kLastTestDomain = 232;

std::string temp_dir() {
  const char* t = std::getenv("TMPDIR");
  return (t != nullptr && *t != '\0') ? t : "/tmp";
}
}  // namespace

void sleep_ms(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }

bool require_all() {
  const auto set_to = [](const char* name, const char* value) {
    const char* v = std::getenv(name);
    return v != nullptr && std::string(v) == value;
  };
  return set_to("CI", "true") || set_to("POISE_REQUIRE_ALL", "1");
}

DomainLease::DomainLease() {
  const std::string dir = temp_dir() + "/poise-test-domains";
  ::mkdir(dir.c_str(), 0777);
  // Start at a pid-dependent offset so concurrent tests rarely contend for the same lock.
  const int span = kLastTestDomain - kFirstTestDomain + 1;
  const int start = static_cast<int>(::getpid()) % span;
  for (int i = 0; i < span; ++i) {
    const int domain = kFirstTestDomain + (start + i) % span;
    const std::string path = dir + "/" + std::to_string(domain) + ".lock";
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) {
      continue;
    }
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
      id_ = domain;
      fd_ = fd;
      return;
    }
    ::close(fd);
  }
  throw std::runtime_error("DomainLease: every test domain is in use");
}

DomainLease::~DomainLease() {
  if (fd_ >= 0) {
    ::flock(fd_, LOCK_UN);
    ::close(fd_);
  }
}

std::optional<std::string> shared_dir() {
  const char* env = std::getenv("POISE_SHARED_DIR");
  std::vector<std::string> candidates;
  if (env != nullptr && *env != '\0') {
    candidates.emplace_back(env);  // when set, the only place looked at
  } else {
    candidates.emplace_back(std::string(POISE_SOURCE_DIR) + "/../shared");
  }
  for (const auto& c : candidates) {
    struct stat st {};
    if (::stat((c + "/broad").c_str(), &st) == 0 && S_ISDIR(st.st_mode)) {
      return c;
    }
  }
  return std::nullopt;
}

std::string bin(const std::string& name) { return std::string(POISE_BIN_DIR) + "/" + name; }

std::string source_path(const std::string& relative) {
  return std::string(POISE_SOURCE_DIR) + "/" + relative;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

Child::Child(const std::vector<std::string>& argv, const std::vector<std::string>& env) {
  static int counter = 0;
  log_path_ = temp_dir() + "/poise-test-child-" + std::to_string(::getpid()) + "-" +
              std::to_string(counter++) + ".log";
  const pid_t pid = ::fork();
  if (pid < 0) {
    throw std::runtime_error(std::string("fork failed: ") + std::strerror(errno));
  }
  if (pid == 0) {
    const int fd = ::open(log_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      ::dup2(fd, STDOUT_FILENO);
      ::dup2(fd, STDERR_FILENO);
      ::close(fd);
    }
    const int devnull = ::open("/dev/null", O_RDONLY);
    if (devnull >= 0) {
      ::dup2(devnull, STDIN_FILENO);
      ::close(devnull);
    }
    ::setpgid(0, 0);
    for (const auto& e : env) {
      ::putenv(const_cast<char*>(e.c_str()));
    }
    std::vector<char*> args;
    args.reserve(argv.size() + 1);
    for (const auto& a : argv) {
      args.push_back(const_cast<char*>(a.c_str()));
    }
    args.push_back(nullptr);
    ::execv(args[0], args.data());
    std::fprintf(stderr, "execv %s failed: %s\n", args[0], std::strerror(errno));
    ::_exit(127);
  }
  pid_ = pid;
}

Child::~Child() {
  if (!status_) {
    ::kill(-pid_, SIGKILL);
    ::kill(pid_, SIGKILL);
    int st = 0;
    ::waitpid(pid_, &st, 0);
  }
  ::unlink(log_path_.c_str());
}

std::optional<int> Child::wait_for(std::chrono::milliseconds timeout) {
  if (status_) {
    return status_;
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  do {
    int st = 0;
    const pid_t r = ::waitpid(pid_, &st, WNOHANG);
    if (r == pid_) {
      status_ = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
      return status_;
    }
    sleep_ms(5);
  } while (std::chrono::steady_clock::now() < deadline);
  return std::nullopt;
}

void Child::signal(int sig) {
  if (!status_) {
    ::kill(pid_, sig);
  }
}

std::string Child::output() const {
  std::ifstream in(log_path_);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

RunResult run(const std::vector<std::string>& argv, std::chrono::milliseconds timeout,
              const std::vector<std::string>& env) {
  Child child(argv, env);
  const auto code = child.wait_for(timeout);
  if (!code) {
    child.signal(SIGKILL);
    child.wait_for(std::chrono::seconds(5));
    return {-1, child.output()};
  }
  return {*code, child.output()};
}

}  // namespace poise::testing
