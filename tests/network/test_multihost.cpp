// GIVEN four hosts (IMU, camera, fusion, recorder) on one LAN with multicast
// WHEN each runs its poise process with default (multicast SPDP) discovery
// THEN the data flows IMU -> fusion -> recorder and camera -> fusion, across the namespaces.
#include "netlab.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

namespace poise::nettest {
namespace {

using namespace std::chrono_literals;
constexpr auto kDiscoveryBound = 15s;  // generous bound on a loaded 2-core machine

TEST(MultiHost, FourHostsMulticastDiscoveryCarriesImuVisionAndAttitude) {
  POISE_REQUIRE_NETLAB();
  testing::DomainLease lease;
  const std::string domain = std::to_string(lease.id());
  NetLab lab({"imu", "camera", "fusion", "recorder"});

  const int64_t t0 = monotonic_ns();
  auto recorder = lab.node("recorder", {"watch", "--domain", domain, "--type", "attitude"});
  auto recorder_imu = lab.node("recorder", {"watch", "--domain", domain, "--type", "imu"});
  auto fusion = lab.node("fusion", {"fusion", "--domain", domain});
  auto imu = lab.node("imu", {"imu", "--domain", domain, "--rate-hz", "100"});
  auto camera = lab.node("camera", {"camera", "--domain", domain, "--rate-hz", "30"});

  const auto at_fusion = wait_event(*fusion, "first", {{"topic", "imu"}}, kDiscoveryBound);
  ASSERT_TRUE(at_fusion) << "fusion got no IMU sample:\n" << fusion->output() << imu->output();
  const auto vision = wait_event(*fusion, "first", {{"topic", "vision_pose"}}, kDiscoveryBound);
  ASSERT_TRUE(vision) << "fusion got no vision pose:\n" << fusion->output() << camera->output();
  const auto attitude = wait_event(*recorder, "first", {{"topic", "attitude/tilt"}}, kDiscoveryBound);
  ASSERT_TRUE(attitude) << "recorder got no attitude:\n" << recorder->output() << fusion->output();
  const auto raw = wait_event(*recorder_imu, "first", {{"topic", "imu"}}, kDiscoveryBound);
  ASSERT_TRUE(raw) << "recorder got no IMU sample:\n" << recorder_imu->output();

  EXPECT_EQ(at_fusion->str("source"), "imu0");
  EXPECT_EQ(vision->str("source"), "cam0");
  EXPECT_EQ(attitude->str("source"), "imu0") << "the relay keeps the sensor id";
  // Figure: process start to first sample delivered, multicast discovery (docs/NETWORK.md).
  const double first_ms = (at_fusion->num("t_ns") - static_cast<double>(t0)) * 1e-6;
  std::printf("[figure] multicast discovery: spawn -> first imu sample at fusion %.0f ms\n",
              first_ms);
  RecordProperty("first_sample_ms", std::to_string(first_ms));

  // Flow continues: after 1 s more, the recorder has received attitude for most IMU samples.
  testing::sleep_ms(1000);
  stop(*imu);
  testing::sleep_ms(200);
  stop(*fusion);
  stop(*recorder);
  const auto sent = find_events(imu->output(), "summary", {{"topic", "imu"}});
  const auto relayed = find_events(recorder->output(), "summary", {{"topic", "attitude/tilt"}});
  ASSERT_EQ(sent.size(), 1U) << imu->output();
  ASSERT_EQ(relayed.size(), 1U) << recorder->output();
  EXPECT_GT(relayed[0].num("received"), 50.0) << "at 100 Hz for > 1 s";
  EXPECT_LE(relayed[0].num("received"), sent[0].num("sent"));
}

}  // namespace
}  // namespace poise::nettest
