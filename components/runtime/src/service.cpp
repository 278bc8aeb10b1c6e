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

}  // namespace poise::runtime
