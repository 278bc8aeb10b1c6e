// Readiness for a service manager: `poise run` under systemd (`Type=notify`, the shipped
// `poise@.service`) tells systemd READY=1 only once every component of the host has started, and
// STOPPING=1 before it stops them. Built on libsystemd's sd_notify (Debian libsystemd-dev, found
// at configure time); without it, or when $NOTIFY_SOCKET is unset (not started by systemd), every
// call is a no-op. The watchdog (ServiceWatchdog) is fed from a health check of the components.
// Install/deploy: docs/DEPLOY.md.
#pragma once

#include "poise/runtime/host.h"

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace poise::runtime {

/// True when poise was built with libsystemd (sd_notify support).
bool service_notify_supported();

/// Sends `state` (e.g. "READY=1") to the service manager; true if it was sent, false when there is
/// no service manager to tell ($NOTIFY_SOCKET unset) or no sd_notify support. A failure to send
/// to a socket that is set is a warning on stderr (the service manager then times the start out).
bool notify_service(const std::string& state);

/// Starts every component of `host` (Host::start) and only then tells the service manager that
/// the service is ready (READY=1 with a STATUS line). If a component fails to start, the exception
/// propagates and nothing is sent.
void start_and_notify(Host& host);

/// Tells the service manager STOPPING=1, then stops the components (Host::stop).
void stop_and_notify(Host& host);

/// The service watchdog: with `WatchdogSec=` (the shipped unit), systemd kills and restarts a
/// service that stops sending WATCHDOG=1. `poise run` sends it from a health check, not a timer:
/// every `interval` it compares what each component has produced (Component::produced()) with
/// the previous check, and sends WATCHDOG=1 only when every watched component has produced
/// something since. A component that stops producing (a hung thread, a dead input, a filter that
/// rejects everything) stops the watchdog; systemd then restarts the service after WatchdogSec.
/// Which components are not producing goes to STATUS= (`systemctl status`) and to stderr, once
/// each time the set changes.
class ServiceWatchdog {
 public:
  using Counts = std::function<std::vector<ComponentOutput>()>;
  /// `counts`: what the components have produced (Host::produced()), read once here as the
  /// baseline and once per check; `interval_ns` between checks (0: off, poll() does nothing);
  /// `now_ns` on the clock poll() is given (monotonic).
  ServiceWatchdog(Counts counts, int64_t interval_ns, int64_t now_ns);

  /// Half of systemd's WatchdogSec= (WATCHDOG_USEC for this process, sd_watchdog_enabled), in ns;
  /// 0 when there is no watchdog (not run by systemd, no WatchdogSec=, built without libsystemd).
  static int64_t interval_from_environment();

  /// Call often (the run loop): at each interval, the check; true when WATCHDOG=1 was sent.
  bool poll(int64_t now_ns);

  [[nodiscard]] bool enabled() const { return interval_ns_ > 0; }
  /// The components that produced nothing between the last two checks (empty: all did).
  [[nodiscard]] const std::vector<std::string>& stalled() const { return stalled_; }

 private:
  Counts counts_;
  int64_t interval_ns_;
  int64_t next_ns_;
  std::map<std::string, uint64_t> last_;
  std::vector<std::string> stalled_;
};

}  // namespace poise::runtime
