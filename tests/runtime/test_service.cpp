// `poise run` under systemd (Type=notify): READY=1 only after every component has started,
// STOPPING=1 before they stop, nothing when a component fails to start. The test owns the
// service manager's side: a unix datagram socket named by NOTIFY_SOCKET, read without blocking
// from inside the components' start()/stop() and after start_and_notify()/stop_and_notify().
#include "poise/runtime/service.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <vector>

namespace poise::runtime {
namespace {

constexpr int kReceiveTimeoutMs = 2000;  // a datagram on a local socket arrives at once

/// The service manager's notification socket, set as NOTIFY_SOCKET for the test's lifetime.
class NotifySocket {
 public:
  NotifySocket() {
    path_ = (std::filesystem::temp_directory_path() /
             ("poise_notify_" + std::to_string(::getpid()) + ".sock"))
                .string();
    std::filesystem::remove(path_);
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path_.c_str(), sizeof(addr.sun_path) - 1);
    if (fd_ < 0 || ::bind(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
      throw std::runtime_error("cannot bind " + path_ + ": " + std::strerror(errno));
    }
    ::setenv("NOTIFY_SOCKET", path_.c_str(), 1);
  }
  ~NotifySocket() {
    ::unsetenv("NOTIFY_SOCKET");
    ::close(fd_);
    std::filesystem::remove(path_);
  }
  NotifySocket(const NotifySocket&) = delete;
  NotifySocket& operator=(const NotifySocket&) = delete;

  /// The next message, waiting up to `timeout_ms` (0: only one already there); "" if none.
  [[nodiscard]] std::string receive(int timeout_ms) const {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, timeout_ms) != 1) {
      return "";
    }
    char buf[512];
    const ssize_t n = ::recv(fd_, buf, sizeof(buf), 0);
    return n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string();
  }
  /// True when a message is waiting (it stays there).
  [[nodiscard]] bool pending() const {
    pollfd p{fd_, POLLIN, 0};
    return ::poll(&p, 1, 0) == 1;
  }

 private:
  std::string path_;
  int fd_ = -1;
};

/// What the probes saw of the socket when they started and stopped.
struct Seen {
  const NotifySocket* socket = nullptr;
  int started = 0;
  int message_pending_at_start = 0;
  int stopped = 0;
  int message_pending_at_stop = 0;
};
Seen seen;

class NotifyProbe : public Component {
 public:
  explicit NotifyProbe(bool fail) : fail_(fail) {}
  void start() override {
    if (fail_) {
      throw std::runtime_error("probe start failure");
    }
    ++seen.started;
    seen.message_pending_at_start += seen.socket->pending() ? 1 : 0;
  }
  void stop() override {
    ++seen.stopped;
    seen.message_pending_at_stop += seen.socket->pending() ? 1 : 0;
  }
  [[nodiscard]] std::string status() const override { return "ok"; }

 private:
  bool fail_;
};

void register_probes() {
  auto& registry = ComponentRegistry::instance();
  if (registry.find("test_notify_probe") == nullptr) {
    registry.add({"test_notify_probe", "notify probe", [](const ComponentSpec&, HostContext&) {
                    return std::make_unique<NotifyProbe>(false);
                  }});
    registry.add({"test_notify_failing", "notify probe that fails to start",
                  [](const ComponentSpec&, HostContext&) { return std::make_unique<NotifyProbe>(true); }});
  }
}

HostSpec spec_of(const std::string& yaml) { return parse_host(YAML::Load(yaml), "test.yaml", "/cfg", ""); }

class ServiceNotify : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!service_notify_supported()) {
      POISE_SKIP("poise was built without libsystemd (Debian libsystemd-dev): no sd_notify support");
    }
    register_probes();
    socket_ = std::make_unique<NotifySocket>();
    seen = Seen{socket_.get()};
  }
  void TearDown() override {
    seen = Seen{};
    socket_.reset();
  }
  std::unique_ptr<NotifySocket> socket_;
  testing::DomainLease domain_;
};

TEST_F(ServiceNotify, GivenNotifySocketWhenEveryComponentHasStartedThenReadyIsSentAndStoppingBeforeStop) {
  Host host(spec_of("components: [{type: test_notify_probe, name: a}, {type: test_notify_probe, name: b},"
                    " {type: test_notify_probe, name: c}]"),
            domain_.id());
  start_and_notify(host);
  EXPECT_EQ(seen.started, 3);
  EXPECT_EQ(seen.message_pending_at_start, 0) << "nothing may be sent before the last component started";
  const std::string ready = socket_->receive(kReceiveTimeoutMs);
  EXPECT_NE(ready.find("READY=1"), std::string::npos) << "got '" << ready << "'";
  EXPECT_NE(ready.find("STATUS=3 component(s) running"), std::string::npos) << "got '" << ready << "'";
  EXPECT_EQ(socket_->receive(0), "") << "exactly one message at start";

  stop_and_notify(host);
  EXPECT_EQ(seen.stopped, 3);
  EXPECT_EQ(seen.message_pending_at_stop, 3) << "STOPPING=1 is sent before the first component stops";
  EXPECT_EQ(socket_->receive(kReceiveTimeoutMs), "STOPPING=1");
}

TEST_F(ServiceNotify, GivenAComponentThatFailsToStartThenReadyIsNeverSent) {
  Host host(spec_of("components: [{type: test_notify_probe, name: a}, {type: test_notify_failing, name: b}]"),
            domain_.id());
  EXPECT_THROW(start_and_notify(host), std::runtime_error);
  EXPECT_EQ(seen.started, 1);
  EXPECT_EQ(socket_->receive(kReceiveTimeoutMs / 4), "") << "no READY=1 when a component failed to start";
}

TEST_F(ServiceNotify, WithoutNotifySocketNothingIsSent) {
  ::unsetenv("NOTIFY_SOCKET");
  EXPECT_FALSE(notify_service("READY=1")) << "not started by a service manager: a no-op";
  EXPECT_EQ(socket_->receive(kReceiveTimeoutMs / 4), "");
}

// The watchdog is a health check: WATCHDOG=1 only when every watched component has produced since
// the previous check; a component without a count (on demand only) is not watched.
TEST_F(ServiceNotify, GivenComponentCountsWhenEachCheckComesThenWatchdogIsSentOnlyWhileEveryWatchedOneProduced) {
  constexpr int64_t kIntervalNs = 5'000'000'000;
  std::vector<ComponentOutput> counts{{"imu0", 0U}, {"pkf", 0U}, {"foxglove", std::nullopt}};
  ServiceWatchdog watchdog([&counts] { return counts; }, kIntervalNs, 0);
  ASSERT_TRUE(watchdog.enabled());
  EXPECT_FALSE(watchdog.poll(kIntervalNs - 1)) << "no check before the first interval ends";
  EXPECT_EQ(socket_->receive(0), "");

  counts[0].produced = 500U;
  counts[1].produced = 480U;
  EXPECT_TRUE(watchdog.poll(kIntervalNs));
  EXPECT_EQ(socket_->receive(kReceiveTimeoutMs), "WATCHDOG=1");
  EXPECT_TRUE(watchdog.stalled().empty());

  counts[0].produced = 1000U;  // pkf stops producing; the foxglove bridge never counts
  EXPECT_FALSE(watchdog.poll(2 * kIntervalNs));
  EXPECT_EQ(socket_->receive(kReceiveTimeoutMs), "STATUS=not producing: pkf");
  EXPECT_EQ(socket_->receive(0), "") << "no WATCHDOG=1 while a component produces nothing";
  EXPECT_EQ(watchdog.stalled(), std::vector<std::string>{"pkf"});

  counts[0].produced = 1500U;
  EXPECT_FALSE(watchdog.poll(3 * kIntervalNs - 1)) << "the next check is one interval after the last";
  EXPECT_FALSE(watchdog.poll(3 * kIntervalNs)) << "pkf still at 480";
  EXPECT_EQ(socket_->receive(0), "") << "the STATUS line is sent once per change";

  counts[0].produced = 2000U;
  counts[1].produced = 481U;
  EXPECT_TRUE(watchdog.poll(4 * kIntervalNs));
  EXPECT_EQ(socket_->receive(kReceiveTimeoutMs), "STATUS=2 component(s) producing");
  EXPECT_EQ(socket_->receive(kReceiveTimeoutMs), "WATCHDOG=1");
}

TEST_F(ServiceNotify, GivenNoWatchdogIntervalThenTheCheckNeverRunsAndNothingIsSent) {
  int reads = 0;
  ServiceWatchdog watchdog([&reads] { ++reads; return std::vector<ComponentOutput>{{"a", 0U}}; }, 0, 0);
  EXPECT_FALSE(watchdog.enabled());
  EXPECT_FALSE(watchdog.poll(3'600'000'000'000));
  EXPECT_EQ(reads, 0) << "the counts are not even read";
  EXPECT_EQ(socket_->receive(kReceiveTimeoutMs / 4), "");
}

// systemd gives the watchdog as WATCHDOG_USEC for the process WATCHDOG_PID; the check runs at half
// of it, so one missed check is not yet a restart.
TEST_F(ServiceNotify, GivenWatchdogUsecForThisProcessThenTheCheckIntervalIsHalfOfIt) {
  ::setenv("WATCHDOG_USEC", "10000000", 1);
  ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
  EXPECT_EQ(ServiceWatchdog::interval_from_environment(), 5'000'000'000);
  ::setenv("WATCHDOG_PID", std::to_string(::getpid() + 1).c_str(), 1);
  EXPECT_EQ(ServiceWatchdog::interval_from_environment(), 0) << "another process's watchdog";
  ::unsetenv("WATCHDOG_PID");
  ::unsetenv("WATCHDOG_USEC");
  EXPECT_EQ(ServiceWatchdog::interval_from_environment(), 0);
}

class CountingProbe : public Component {
 public:
  explicit CountingProbe(std::optional<uint64_t> n) : n_(n) {}
  [[nodiscard]] std::optional<uint64_t> produced() const override { return n_; }

 private:
  std::optional<uint64_t> n_;
};

TEST(HostProduced, GivenComponentsWhenAskedThenEachCountComesWithItsInstanceNameInHostFileOrder) {
  auto& registry = ComponentRegistry::instance();
  if (registry.find("test_counting_probe") == nullptr) {
    registry.add({"test_counting_probe", "counting probe", [](const ComponentSpec& spec, HostContext&) {
                    return std::make_unique<CountingProbe>(spec.params["n"] ? std::optional<uint64_t>(spec.params["n"].as<uint64_t>())
                                                                            : std::nullopt);
                  }});
  }
  testing::DomainLease domain;
  const Host host(spec_of("components: [{type: test_counting_probe, name: b, params: {n: 7}},"
                          " {type: test_counting_probe, name: a}]"),
                  domain.id());
  const auto p = host.produced();
  ASSERT_EQ(p.size(), 2U);
  EXPECT_EQ(p[0].name, "b");
  EXPECT_EQ(p[0].produced, std::optional<uint64_t>(7U));
  EXPECT_EQ(p[1].name, "a");
  EXPECT_FALSE(p[1].produced.has_value());
}

}  // namespace
}  // namespace poise::runtime
