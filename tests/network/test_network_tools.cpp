// poise's own tools on a secured network and through a Discovery Server (issue 22): `poise record`,
// `poise echo` and `poise topics` create their participant with the one factory every poise
// process uses (poise::dds::create_participant), so they apply POISE_SECURITY_* and the discovery
// setup like the nodes, and become a super client of a discovery server by themselves.
#include "netlab.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <regex>

namespace poise::nettest {
namespace {

using namespace std::chrono_literals;
constexpr auto kDiscoveryBound = 20s;
constexpr auto kCommandBound = 60s;  // a tool's whole run, on a loaded 2-core machine

std::vector<std::string> secure(const std::string& identity) {
  return {"POISE_SECURITY_DIR=" + std::string(POISE_NET_SECURITY_DIR) + "/good",
          "POISE_SECURITY_IDENTITY=" + identity};
}

/// "received R, written W" of `topic` in a `poise record` summary (-1 when the topic is absent).
long recorded(const std::string& output, const std::string& topic) {
  std::smatch m;
  const std::regex row("\\n  " + std::regex_replace(topic, std::regex("/"), "\\/") +
                       " \\([^)]*\\): received [0-9]+, written ([0-9]+)");
  return std::regex_search(output, m, row) ? std::stol(m[1]) : -1;
}

// GIVEN a secured IMU host (imu identity) and fusion host (fusion identity) publishing `imu` and
// `attitude/tilt`
// WHEN `poise record --all` runs on a third host with the `recorder` identity (subscribe `*`)
// THEN it records both topics, and the recording replays (read back by `poise echo`).
TEST(NetworkTools, SecuredRecordWithTheRecorderIdentityRecordsEveryTopicAndReplays) {
  POISE_REQUIRE_NETLAB();
  testing::DomainLease lease;
  const std::string domain = std::to_string(lease.id());
  NetLab lab({"imu", "fusion", "recorder"});
  auto fusion = lab.node("fusion", {"fusion", "--domain", domain}, secure("fusion"));
  auto imu = lab.node("imu", {"imu", "--domain", domain, "--rate-hz", "100"}, secure("imu"));
  ASSERT_TRUE(wait_event(*fusion, "first", {{"topic", "imu"}}, kDiscoveryBound))
      << fusion->output() << imu->output();
  const std::string file = "/tmp/poise-net-record-" + std::to_string(::getpid()) + ".mcap";
  const RemoveOnExit remove_file{file};
  const auto record = testing::run(
      lab.in_host("recorder", {testing::bin("poise"), "record", "-o", file, "--all", "--duration",
                               "8", "--domain", domain}),
      kCommandBound, [&] {
        std::vector<std::string> env = secure("recorder");
        env.push_back("POISE_DDS_PROFILE=poise_udp");
        return env;
      }());
  ASSERT_EQ(record.exit_code, 0) << record.output;
  EXPECT_GT(recorded(record.output, "imu"), 0) << record.output;
  EXPECT_GT(recorded(record.output, "attitude/tilt"), 0) << record.output;

  // The recording replays: published again (outside the lab, loopback) and read back.
  testing::DomainLease replay_lease;
  const std::vector<std::string> loopback{"POISE_DDS_PROFILE=poise_loopback"};
  testing::Child replay({testing::bin("poise"), "replay", file, "--domain",
                         std::to_string(replay_lease.id()), "--loop"},
                        loopback);
  const auto echo = testing::run({testing::bin("poise"), "echo", "attitude/tilt", "--count", "3",
                                  "--domain", std::to_string(replay_lease.id()), "--timeout", "20"},
                                 kCommandBound, loopback);
  EXPECT_EQ(echo.exit_code, 0) << echo.output << replay.output();
  EXPECT_NE(echo.output.find("imu0"), std::string::npos) << echo.output;
}

// GIVEN multicast dropped and an IMU host that finds others only through `fast-discovery-server`
// WHEN `poise echo imu` and `poise topics` run on another host as clients of the server, set by
// ROS_DISCOVERY_SERVER or by the XML client profile (a plain client: the tools make themselves
// super clients)
// THEN echo prints IMU samples and topics lists `imu`.
TEST(NetworkTools, EchoAndTopicsThroughADiscoveryServerWithMulticastDropped) {
  POISE_REQUIRE_NETLAB();
  const std::string server_bin = discovery_server_binary();
  if (server_bin.empty()) {
    POISE_SKIP("fast-discovery-server not installed (apt-get install fastdds-tools)");
  }
  testing::DomainLease lease;
  const std::string domain = std::to_string(lease.id());
  NetLab lab({"server", "imu", "tools"}, /*multicast=*/false);
  const std::string server_ip = lab.ip("server");
  testing::Child server(lab.in_host("server", {server_bin, "-i", "0", "-l", server_ip, "-p", "11811"}));
  const RemoveOnExit xml{write_discovery_client_xml(server_ip)};
  const std::vector<std::string> by_env{"ROS_DISCOVERY_SERVER=" + server_ip + ":11811"};
  const std::vector<std::string> by_xml{"POISE_DDS_PROFILE=poise_ds_client", "POISE_QOS_FILE=" + xml.path};
  auto imu = lab.node("imu", {"imu", "--domain", domain, "--rate-hz", "50"}, by_env);
  for (const auto& env : {by_env, by_xml}) {
    std::vector<std::string> full{"POISE_DDS_PROFILE=poise_udp"};
    full.insert(full.end(), env.begin(), env.end());
    const auto echo = testing::run(
        lab.in_host("tools", {testing::bin("poise"), "echo", "imu", "--count", "3", "--domain",
                              domain, "--timeout", "20"}),
        kCommandBound, full);
    EXPECT_EQ(echo.exit_code, 0) << env.front() << "\n" << echo.output << server.output();
    EXPECT_NE(echo.output.find("imu0"), std::string::npos) << echo.output;
    const auto topics = testing::run(
        lab.in_host("tools", {testing::bin("poise"), "topics", "--duration", "5", "--domain", domain}),
        kCommandBound, full);
    EXPECT_EQ(topics.exit_code, 0) << topics.output;
    EXPECT_TRUE(std::regex_search(topics.output, std::regex("\\nimu +poise::msg::ImuSample +1 ")))
        << env.front() << "\n" << topics.output;
  }
}

}  // namespace
}  // namespace poise::nettest
