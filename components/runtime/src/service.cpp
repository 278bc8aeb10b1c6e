#include "poise/runtime/service.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>

#if POISE_HAVE_SYSTEMD
#include <systemd/sd-daemon.h>
#endif

namespace poise::runtime {

bool service_notify_supported() { return POISE_HAVE_SYSTEMD != 0; }

bool notify_service(const std::string& state) {
  const char* socket = std::getenv("NOTIFY_SOCKET");
  if (socket == nullptr || *socket == '\0') {
    return false;
  }
#if POISE_HAVE_SYSTEMD
  const int r = sd_notify(0, state.c_str());
  if (r < 0) {
    std::fprintf(stderr, "poise: warning: cannot notify the service manager at %s: %s\n", socket,
                 std::strerror(-r));
  }
  return r > 0;
#else
  (void)state;
  return false;
#endif
}

void start_and_notify(Host& host) {
  host.start();
  notify_service("READY=1\nSTATUS=" + std::to_string(host.size()) + " component(s) running");
}

void stop_and_notify(Host& host) {
  notify_service("STOPPING=1");
  host.stop();
}

ServiceWatchdog::ServiceWatchdog(Counts counts, int64_t interval_ns, int64_t now_ns)
    : counts_(std::move(counts)), interval_ns_(interval_ns > 0 ? interval_ns : 0), next_ns_(now_ns + interval_ns_) {
  if (enabled()) {
    for (const auto& c : counts_()) {
      if (c.produced) {
        last_[c.name] = *c.produced;
      }
    }
  }
}

int64_t ServiceWatchdog::interval_from_environment() {
#if POISE_HAVE_SYSTEMD
  uint64_t usec = 0;
  if (sd_watchdog_enabled(0, &usec) > 0 && usec > 0) {
    return static_cast<int64_t>(usec / 2) * 1000;
  }
#endif
  return 0;
}

bool ServiceWatchdog::poll(int64_t now_ns) {
  if (!enabled() || now_ns < next_ns_) {
    return false;
  }
  next_ns_ = now_ns + interval_ns_;
  std::vector<std::string> stalled;
  std::size_t watched = 0;
  for (const auto& c : counts_()) {
    if (!c.produced) {
      continue;
    }
    ++watched;
    const auto it = last_.find(c.name);
    if (it != last_.end() && *c.produced <= it->second) {
      stalled.push_back(c.name);
    }
    last_[c.name] = *c.produced;
  }
  if (stalled != stalled_) {
    std::string names;
    for (const auto& n : stalled) {
      names += (names.empty() ? "" : ", ") + n;
    }
    const std::string status = stalled.empty()
                                   ? std::to_string(watched) + " component(s) producing"
                                   : "not producing: " + names;
    if (!stalled.empty()) {
      std::fprintf(stderr,
                   "poise: watchdog: %s produced nothing in the last %.1f s: not telling systemd "
                   "WATCHDOG=1 (it restarts the service after WatchdogSec)\n",
                   names.c_str(), static_cast<double>(interval_ns_) * 1e-9);
    } else {
      std::fprintf(stderr, "poise: watchdog: every component producing again\n");
    }
    notify_service("STATUS=" + status);
    stalled_ = std::move(stalled);
  }
  return stalled_.empty() && notify_service("WATCHDOG=1");
}

}  // namespace poise::runtime
