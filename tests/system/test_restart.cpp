// Multi-process deployment: the IMU side and a fusion component run as separate processes; the
// fusion process is killed (SIGKILL) and restarted: the IMU side keeps publishing and the new
// fusion process resumes receiving and publishing estimates.
#include "poise/testing/testing.h"

#include "poise/dds/participant.h"

#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include <gtest/gtest.h>

#include <atomic>
#include <csignal>
#include <fstream>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;
constexpr auto kResumeBound = 10s;  // restart -> estimates flowing again (discovery + start-up)

TEST(Restart, KilledFusionProcessResumesAndTheOthersKeepRunning) {
  DomainLease domain;
  const std::string d = std::to_string(domain.id());
  const std::string link = "/tmp/poise-restart-imu-" + std::to_string(::getpid());
  const std::string host = "/tmp/poise-restart-" + std::to_string(::getpid()) + ".yaml";
  std::ofstream(host) << "components:\n"
                         "  - {type: sim_imu, params: {link: " << link << ", scenario: random_motion, rate_hz: 100}}\n"
                         "  - {type: imu_driver, name: imu0, params: {port: " << link << "}}\n";
  dds::Participant participant({domain.id(), "", "", "restart_monitor"});
  std::atomic<uint64_t> imu{0};
  std::atomic<uint64_t> estimates{0};
  dds::Reader<msg::ImuSamplePubSubType> imu_reader(participant, "imu",
                                                   [&](const auto&, const auto&) { imu.fetch_add(1); });
  dds::Reader<msg::AttitudeEstimatePubSubType> est_reader(
      participant, "attitude/parallel_kf", [&](const auto&, const auto&) { estimates.fetch_add(1); });

  Child imu_side({bin("poise"), "run", host, "--domain", d, "--quiet"});
  auto fusion = std::make_unique<Child>(std::vector<std::string>{bin("poise"), "parallel-kf", "--domain", d, "--quiet"});
  ASSERT_TRUE(wait_until([&] { return estimates.load() > 100; }, 30s))
      << "no estimates; imu side:\n" << imu_side.output() << "\nfusion:\n" << fusion->output();

  // WHEN the fusion process is killed THEN estimates stop and IMU samples keep flowing.
  fusion->signal(SIGKILL);
  ASSERT_TRUE(fusion->wait_for(5s).has_value());
  fusion.reset();
  sleep_ms(500);
  const uint64_t estimates_after_kill = estimates.load();
  const uint64_t imu_after_kill = imu.load();
  // The IMU stream goes on (bounded wait: a loaded machine can stall it briefly).
  EXPECT_TRUE(wait_until([&] { return imu.load() - imu_after_kill > 100; }, 10s))
      << "the IMU side stopped when fusion died";
  EXPECT_LE(estimates.load() - estimates_after_kill, 5U) << "estimates kept coming after the kill";

  // WHEN it is restarted THEN estimates resume within the bound.
  const auto restart = std::chrono::steady_clock::now();
  fusion = std::make_unique<Child>(std::vector<std::string>{bin("poise"), "parallel-kf", "--domain", d, "--quiet"});
  const uint64_t before = estimates.load();
  ASSERT_TRUE(wait_until([&] { return estimates.load() > before + 100; }, kResumeBound))
      << "fusion did not resume; its output:\n" << fusion->output();
  const double resume_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - restart).count();
  std::printf("fusion resumed %.2f s after restart\n", resume_s);
  EXPECT_EQ(imu_side.wait_for(1ms), std::nullopt) << "the IMU side exited: " << imu_side.output();
  ::unlink(host.c_str());
}

}  // namespace
}  // namespace poise::testing
