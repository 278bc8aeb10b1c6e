// GIVEN four hosts (IMU, camera, fusion, recorder) on one LAN with multicast
// WHEN each runs its poise process with default (multicast SPDP) discovery
// THEN the data flows IMU -> fusion -> recorder and camera -> fusion, across the namespaces.
#include "netlab.h"

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>

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
  EXPECT_GT(relayed[0].num("received"), 20.0) << "100 Hz for > 1 s (bound for a loaded machine)";
  EXPECT_LE(relayed[0].num("received"), sent[0].num("sent"));
}

/// True when `pid` has exited (gone, or a zombie nobody reaped yet: e.g. pid 1 of a container
/// that does not reap orphans).
bool process_gone(int pid) {
  if (::kill(pid, 0) != 0 && errno == ESRCH) {
    return true;
  }
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string comm_and_state;
  std::getline(stat, comm_and_state);
  const size_t paren = comm_and_state.rfind(')');
  return paren != std::string::npos && paren + 2 < comm_and_state.size() &&
         comm_and_state[paren + 2] == 'Z';
}

// GIVEN the real components: on the IMU host a simulated serial board (`poise sim-imu`, a pty) read
// by the real serial driver (`poise imu`), on the fusion host the real parallel_kf node
// WHEN they run in separate namespaces THEN the recorder host receives IMU samples from the driver
// and attitude from the estimator; WHEN the driver is killed -9 and restarted THEN IMU samples and
// attitude resume.
TEST(MultiHost, RealImuDriverAndParallelKfAcrossHosts) {
  POISE_REQUIRE_NETLAB();
#if !defined(POISE_NET_HAVE_REAL_FUSION) || !defined(POISE_NET_HAVE_IMU_TOOLS)
  POISE_SKIP("the IMU driver (poise_imu_dev) or estimator node libraries are not in this build");
#else
  testing::DomainLease lease;
  const std::string domain = std::to_string(lease.id());
  NetLab lab({"imu", "fusion", "recorder"});
  const std::string link = "/tmp/poise-net-imu-" + std::to_string(::getpid());
  const RemoveOnExit remove_link{link};  // the board may be killed before it removes it
  const std::string tools = testing::bin("poise_imu_dev");
  auto board = lab.process("imu", {tools, "sim-imu", "--link", link, "--rate", "100", "--quiet"});
  ASSERT_TRUE(testing::wait_until([&] { return ::access(link.c_str(), F_OK) == 0; }, 10s))
      << board->output();
  const std::vector<std::string> driver_argv{tools,       "imu",       "--port",  link,
                                             "--name",    "imu0",      "--dds-profile", "poise_udp",
                                             "--domain",  domain,      "--quiet"};
  auto driver = lab.process("imu", driver_argv);
  auto fusion = lab.process("fusion", {testing::bin("poise_net_real_fusion"), domain, "pkf"});
  auto raw = lab.node("recorder", {"watch", "--domain", domain, "--type", "imu"});
  auto attitude = lab.node("recorder", {"watch", "--domain", domain, "--type", "attitude",
                                        "--topic", "attitude/parallel_kf"});
  // What reaches the fusion host from the driver, beside the estimator: when attitude does not
  // resume, this tells the network (nothing arrived there) from the estimator (it arrived).
  auto raw_at_fusion = lab.node("fusion", {"watch", "--domain", domain, "--type", "imu"});
  ASSERT_TRUE(wait_event(*raw, "first", {{"source", "imu0"}}, kDiscoveryBound))
      << raw->output() << driver->output() << board->output();
  ASSERT_TRUE(wait_event(*attitude, "first", {{"source", "pkf"}}, kDiscoveryBound))
      << attitude->output() << fusion->output();

  driver->signal(SIGKILL);
  ASSERT_TRUE(driver->wait_for(5s));
  testing::sleep_ms(1000);
  const int64_t t_restart = monotonic_ns();
  driver = lab.process("imu", driver_argv);
  const auto imu_back = wait_event(*raw, "resume", {{"source", "imu0"}}, kDiscoveryBound, t_restart);
  ASSERT_TRUE(imu_back) << raw->output() << driver->output() << board->output();
  const auto att_back =
      wait_event(*attitude, "resume", {{"source", "pkf"}}, kDiscoveryBound, t_restart);
  if (!att_back) {
    const std::optional<int> fusion_exit = fusion->wait_for(0ms);
    FAIL() << attitude->output() << "fusion process: "
           << (fusion_exit ? "exited with " + std::to_string(*fusion_exit) : std::string("running"))
           << "\n" << fusion->output() << "IMU at the fusion host:\n" << raw_at_fusion->output();
  }
  std::printf("[figure] real imu driver kill -9 + restart after 1 s: restart -> imu at recorder "
              "%.0f ms, -> attitude (parallel_kf) at recorder %.0f ms\n",
              (imu_back->num("t_ns") - static_cast<double>(t_restart)) * 1e-6,
              (att_back->num("t_ns") - static_cast<double>(t_restart)) * 1e-6);
  EXPECT_EQ(imu_back->str("restart"), "1") << "a new driver process is a new writer";
#endif
}

bool namespace_exists(const std::string& name) {
  const auto list = testing::run({"/bin/sh", "-c", "ip netns list"}, 10s);
  std::istringstream in(list.output);
  std::string line;
  while (std::getline(in, line)) {
    if (line.substr(0, line.find(' ')) == name) {
      return true;
    }
  }
  return false;
}

// GIVEN a NetLab with a process running on a host WHEN the NetLab is destroyed
// THEN its namespaces are gone and the process was killed (cleanup even when a test fails midway).
TEST(NetLab, DestructorRemovesNamespacesAndKillsTheirProcesses) {
  POISE_REQUIRE_NETLAB();
  std::string ns;
  int pid = -1;
  {
    NetLab lab({"a", "b"});
    ns = lab.ns("a");
    ASSERT_TRUE(namespace_exists(ns));
    // A process that is not a Child of this test (so only the NetLab can end it).
    const auto r = testing::run(lab.in_host("a", {"/bin/sh", "-c", "sleep 60 >/dev/null 2>&1 & echo $!"}), 10s);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    pid = std::stoi(r.output);
    ASSERT_EQ(::kill(pid, 0), 0) << "the background process runs in the namespace";
  }
  EXPECT_FALSE(namespace_exists(ns));
  EXPECT_TRUE(testing::wait_until([&] { return process_gone(pid); }, 5s))
      << "process " << pid << " still alive";
}

// GIVEN namespaces left by a run whose process is gone (e.g. killed by a ctest timeout)
// WHEN a new NetLab starts THEN they are removed; namespaces of live runs are kept.
TEST(NetLab, SweepsNamespacesOfDeadRunsOnly) {
  POISE_REQUIRE_NETLAB();
  const pid_t dead = ::fork();
  if (dead == 0) {
    ::_exit(0);
  }
  ASSERT_GT(dead, 0);
  ::waitpid(dead, nullptr, 0);
  const std::string stale = "poisenet" + std::to_string(dead) + "-0-switch";
  const std::string live = "poisenet" + std::to_string(::getpid()) + "-999-x";
  ASSERT_EQ(testing::run({"/bin/sh", "-c", "ip netns add " + stale + " && ip netns add " + live}, 10s)
                .exit_code,
            0);
  NetLab::sweep_stale();
  EXPECT_FALSE(namespace_exists(stale));
  EXPECT_TRUE(namespace_exists(live)) << "a live run's namespace must survive the sweep";
  testing::run({"/bin/sh", "-c", "ip netns del " + live}, 10s);
}

}  // namespace
}  // namespace poise::nettest
