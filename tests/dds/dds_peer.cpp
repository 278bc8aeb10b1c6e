// Test peer: publishes one deterministic message of a given type repeatedly (every 10 ms) on a
// domain until it has written for --duration-ms, so a reader in another process can check that all
// fields arrive intact. Usage: poise_dds_peer CASE DOMAIN SALT DURATION_MS
#include "type_cases.h"

#include "poise/dds/participant.h"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

namespace {
struct Publish {
  int domain;
  int salt;
  int duration_ms;
  template <typename Case>
  void operator()() const {
    poise::dds::Participant participant({domain, "", "", "poise_dds_peer"});
    poise::dds::Writer<typename Case::PubSubType> writer(participant, Case::kTopic);
    const auto message = Case::make(salt);
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(duration_ms);
    while (std::chrono::steady_clock::now() < end) {
      writer.write(message);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
};
}  // namespace

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: poise_dds_peer CASE DOMAIN SALT DURATION_MS\n");
    return 2;
  }
  const Publish publish{std::atoi(argv[2]), std::atoi(argv[3]), std::atoi(argv[4])};
  if (!poise::testing::with_case(argv[1], publish)) {
    std::fprintf(stderr, "unknown case %s\n", argv[1]);
    return 2;
  }
  return 0;
}
