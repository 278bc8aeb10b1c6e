// NetLab: several "hosts" on one machine for the network tests. Each host is a network namespace
// with one interface eth0 (10.77.0.N/24), a veth pair to a bridge that lives in its own switch
// namespace, so the machine's own network is never touched. Everything is created by the
// constructor and removed by the destructor (processes in the namespaces are killed first);
// namespaces left behind by a crashed run (owner pid gone) are swept by the next NetLab.
// Needs root (CAP_NET_ADMIN + CAP_SYS_ADMIN); tests use POISE_REQUIRE_NETLAB() to skip otherwise.
#pragma once

#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace poise::nettest {

/// Empty when namespaces can be created here; otherwise why not (for POISE_SKIP).
std::string netlab_unavailable_reason();

/// CLOCK_MONOTONIC in ns: the clock poise_net_node stamps its events with.
int64_t monotonic_ns();

class NetLab {
 public:
  /// Hosts get 10.77.0.1, .2, ... in order. `multicast` false: the switch drops multicast (bridge
  /// ports with mcast_flood off), the interfaces have no MULTICAST flag and no multicast route, so
  /// SPDP multicast discovery cannot work (discovery server tests).
  explicit NetLab(const std::vector<std::string>& hosts, bool multicast = true);
  ~NetLab();
  NetLab(const NetLab&) = delete;
  NetLab& operator=(const NetLab&) = delete;

  [[nodiscard]] std::string ns(const std::string& host) const;
  [[nodiscard]] std::string ip(const std::string& host) const;
  /// argv that runs `argv` inside the host's namespace.
  [[nodiscard]] std::vector<std::string> in_host(const std::string& host,
                                                 const std::vector<std::string>& argv) const;
  /// Starts poise_net_node ARGS on `host` with the UDP-only participant profile (shared memory
  /// would bypass the namespaces) plus `env`.
  [[nodiscard]] std::unique_ptr<testing::Child> node(const std::string& host,
                                                     const std::vector<std::string>& args,
                                                     const std::vector<std::string>& env = {}) const;
  /// Starts any executable `argv` on `host` with the UDP-only participant profile plus `env`.
  [[nodiscard]] std::unique_ptr<testing::Child> process(const std::string& host,
                                                        const std::vector<std::string>& argv,
                                                        const std::vector<std::string>& env = {}) const;
  /// Takes the host's link down or up (the switch side of its veth pair: a cable pulled).
  void set_link(const std::string& host, bool up) const;

  /// Removes namespaces of NetLabs whose process is gone. Called by every constructor.
  static void sweep_stale();

 private:
  void cleanup() noexcept;
  std::string prefix_;
  std::vector<std::string> hosts_;
  std::vector<std::string> created_;  // namespaces, in creation order
};

/// One "@name key=value ..." line printed by poise_net_node.
struct Event {
  std::string name;
  std::map<std::string, std::string> fields;
  [[nodiscard]] std::string str(const std::string& key) const;
  /// The field as a number; throws if it is absent or not a number.
  [[nodiscard]] double num(const std::string& key) const;
};

/// Every event line in `output`, in order.
std::vector<Event> parse_events(const std::string& output);

/// Events named `name` whose fields include all of `match`.
std::vector<Event> find_events(const std::string& output, const std::string& name,
                               const std::map<std::string, std::string>& match = {});

/// Waits (bounded) until `child` printed an event `name` matching `match` (and, if `after_ns` > 0,
/// with t_ns >= after_ns); returns the first such event.
std::optional<Event> wait_event(const testing::Child& child, const std::string& name,
                                const std::map<std::string, std::string>& match,
                                std::chrono::milliseconds timeout, int64_t after_ns = 0);

/// The environment entry (CYCLONEDDS_URI=...) that restricts Cyclone DDS to loopback with unicast
/// discovery of the local participants, matching poise's `poise_loopback` profile.
std::string cyclone_loopback_config();

/// "1,2.5,-3" -> {1, 2.5, -3} (the lists the Cyclone programs print).
std::vector<double> split_doubles(const std::string& list);

/// Removes a path (e.g. the pty symlink of a `poise sim-imu` board that was killed) when it goes
/// out of scope.
struct RemoveOnExit {
  std::string path;
  ~RemoveOnExit();
};

/// A fresh directory /tmp/<prefix>-<pid> (created by the constructor, `ok` false when that failed),
/// removed with its content when it goes out of scope.
struct TempDir {
  explicit TempDir(const std::string& prefix);
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string path;
  bool ok = false;
};

/// A copy of config/qos/discovery_server_client.xml pointing at `server_ip` (port 11811), in /tmp;
/// returns its path (remove it with RemoveOnExit).
std::string write_discovery_client_xml(const std::string& server_ip);

/// The `fast-discovery-server` executable (Debian fastdds-tools), or empty when not installed.
std::string discovery_server_binary();

/// Sends SIGINT and waits (bounded) for the exit so the @summary lines are printed.
void stop(testing::Child& child);

}  // namespace poise::nettest

/// Skips the test with the reason when network namespaces are unavailable (not root).
#define POISE_REQUIRE_NETLAB()                                                             \
  do {                                                                                     \
    const std::string netlab_reason = ::poise::nettest::netlab_unavailable_reason();       \
    if (!netlab_reason.empty()) {                                                          \
      POISE_SKIP(netlab_reason);                                                           \
    }                                                                                      \
  } while (false)
