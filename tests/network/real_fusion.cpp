// poise_net_real_fusion: the real parallel_kf estimator node (components/nodes, via the runtime's
// Host) as the fusion host's process in the fault tests, instead of poise_net_node's relay.
// Usage: poise_net_real_fusion DOMAIN NAME   (runs until SIGINT/SIGTERM; publishes attitude/NAME)
// Participant profile and security come from the environment, as for every poise process.
// Prints "@start", then once a second "status t_ns=... <the component's status line>" (what it
// received, fused, refused as stale or rejected), so that a test that fails shows the fusion's side.
#include "poise/nodes/register.h"
#include "poise/runtime/host.h"

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <exception>
#include <string>
#include <thread>

namespace {
std::atomic<bool> g_stop{false};
void on_signal(int /*sig*/) { g_stop.store(true); }

long long now_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<long long>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: poise_net_real_fusion DOMAIN NAME\n");
    return 2;
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  try {
    std::printf("@start role=real_fusion pid=%d t_ns=%lld\n", static_cast<int>(::getpid()), now_ns());
    std::fflush(stdout);
    auto& registry = poise::runtime::ComponentRegistry::instance();
    if (registry.find("parallel_kf") == nullptr) {
      poise::nodes::register_parallel_kf_node(registry);
    }
    poise::runtime::HostSpec spec;
    poise::runtime::ComponentSpec component;
    component.type = "parallel_kf";
    component.name = argv[2];
    component.origin = "poise_net_real_fusion";
    spec.components.push_back(component);
    poise::runtime::Host host(spec, std::atoi(argv[1]));
    host.start();
    long long next_status = now_ns() + 1000000000LL;
    while (!g_stop.load()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      if (now_ns() >= next_status) {
        next_status += 1000000000LL;
        for (const std::string& line : host.status()) {
          std::printf("status t_ns=%lld %s\n", now_ns(), line.c_str());
        }
        std::fflush(stdout);
      }
    }
    host.stop();
  } catch (const std::exception& e) {
    std::printf("@error what=\"%s\"\n", e.what());
    std::fprintf(stderr, "poise_net_real_fusion: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
