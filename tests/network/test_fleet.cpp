// The fleet figure (issue 37): N robots (10, 20) as network namespaces, multicast dropped, one
// fast-discovery-server. Each robot runs what a user runs: a simulated serial IMU board
// (`poise sim-imu`), and `poise run` with the IMU driver and a parallel KF on its own IMU topic,
// plus a watcher of every robot's estimates. Measured: spawn -> every robot sees every robot's
// estimate; CPU and bandwidth per robot over a window. Manual (a machine-filling measurement, not
// a check): DISABLED_ in CTest, run it with
//   build/tests/network/poise_network_tests --gtest_also_run_disabled_tests
//     --gtest_filter='*Fleet*' | grep figure     (one line; root)
#include "netlab.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>

namespace poise::nettest {
namespace {

using namespace std::chrono_literals;
/// IMU rate per robot: 25 Hz keeps 20 robots (60 processes) within a 2-core machine; a real robot
/// runs 100-200 Hz, so bandwidth scales with the rate, discovery time does not.
constexpr const char* kImuRateHz = "25";
/// Bound for the whole fleet to see every estimate (a bound for the test, not a figure).
constexpr auto kFleetBound = 60s;
/// The window CPU and bandwidth are averaged over, once every estimate is seen everywhere.
constexpr int kWindowMs = 10000;
constexpr const char* kServerPort = "11811";

/// CPU time (user + system, all threads) of a process so far, in seconds; -1 when it is gone.
double cpu_seconds(int pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) {
    return -1.0;
  }
  // Fields after the ")" that ends the command name: state is field 3, utime 14, stime 15.
  std::istringstream rest(line.substr(line.rfind(')') + 2));
  std::string field;
  double utime = 0.0, stime = 0.0;
  for (int i = 3; i <= 15 && rest >> field; ++i) {
    if (i == 14) {
      utime = std::stod(field);
    } else if (i == 15) {
      stime = std::stod(field);
    }
  }
  return (utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

/// Bytes through the host's eth0 so far (received + sent).
double eth0_bytes(const NetLab& lab, const std::string& host) {
  const auto r = testing::run(lab.in_host(host, {"/bin/sh", "-c",
                                                 "cat /sys/class/net/eth0/statistics/rx_bytes "
                                                 "/sys/class/net/eth0/statistics/tx_bytes"}),
                              10s);
  std::istringstream in(r.output);
  double rx = 0.0, tx = 0.0;
  in >> rx >> tx;
  return rx + tx;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

class FleetFigure : public ::testing::TestWithParam<int> {};

// GIVEN N robots on a network that drops multicast, each a client of one discovery server
// WHEN every robot starts its IMU board, driver + parallel KF, and a watcher of all estimates
// THEN every watcher receives every robot's estimate; the time, CPU and bandwidth are reported.
TEST_P(FleetFigure, DISABLED_EveryRobotSeesEveryEstimate) {
  POISE_REQUIRE_NETLAB();
  const std::string server_bin = discovery_server_binary();
  if (server_bin.empty()) {
    POISE_SKIP("fast-discovery-server not installed (apt-get install fastdds-tools)");
  }
  if (::access(testing::bin("poise").c_str(), X_OK) != 0) {
    POISE_SKIP("build the poise executable first (target poise): the fleet runs it");
  }
  const int n = GetParam();
  testing::DomainLease lease;
  const std::string domain = std::to_string(lease.id());
  std::vector<std::string> hosts{"server"};
  for (int i = 1; i <= n; ++i) {
    hosts.push_back("r" + std::to_string(i));
  }
  NetLab lab(hosts, /*multicast=*/false);
  const TempDir workdir("poise-fleet");
  ASSERT_TRUE(workdir.ok) << workdir.path;
  const std::string& dir = workdir.path;
  const std::vector<std::string> env{"ROS_DISCOVERY_SERVER=" + lab.ip("server") + ":" + kServerPort};
  testing::Child server(lab.in_host("server", {server_bin, "-i", "0", "-l", lab.ip("server"), "-p",
                                               kServerPort}));

  struct Robot {
    std::string host;
    std::unique_ptr<testing::Child> board, run, watch;
  };
  std::vector<Robot> robots;
  const int64_t t_spawn = monotonic_ns();
  for (int i = 1; i <= n; ++i) {
    Robot r;
    r.host = "r" + std::to_string(i);
    const std::string link = dir + "/" + r.host + ".pty";
    const std::string yaml = dir + "/" + r.host + ".yaml";
    std::ofstream(yaml) << "domain: " << domain << "\nparticipant_profile: poise_udp\n"
                        << "topics: {imu: imu_" << r.host << "}\ncomponents:\n"
                        << "  - type: imu_driver\n    name: imu_" << r.host << "\n    params: {port: "
                        << link << "}\n  - type: parallel_kf\n    name: " << r.host << "\n";
    r.board = lab.process(r.host, {testing::bin("poise"), "sim-imu", "--link", link, "--rate",
                                   kImuRateHz, "--seed", std::to_string(i), "--quiet"});
    ASSERT_TRUE(testing::wait_until([&] { return ::access(link.c_str(), F_OK) == 0; }, 20s))
        << r.board->output();
    r.run = lab.process(r.host, {testing::bin("poise"), "run", yaml}, env);
    r.watch = lab.node(r.host, {"watch", "--domain", domain, "--type", "attitude", "--topic",
                                "attitude/parallel_kf"},
                       env);
    robots.push_back(std::move(r));
  }
  const int64_t t_started = monotonic_ns();

  // Every watcher must see every robot's estimate (source = the robot's parallel_kf instance).
  std::set<std::string> all;
  for (const Robot& r : robots) {
    all.insert(r.host);
  }
  std::vector<double> last_ms(robots.size(), -1.0);
  const bool complete = testing::wait_until(
      [&] {
        bool every = true;
        for (size_t k = 0; k < robots.size(); ++k) {
          if (last_ms[k] >= 0.0) {
            continue;
          }
          std::set<std::string> seen;
          double last_t = 0.0;
          for (const Event& e : find_events(robots[k].watch->output(), "first")) {
            seen.insert(e.str("source"));
            last_t = std::max(last_t, e.num("t_ns"));
          }
          if (seen == all) {
            last_ms[k] = (last_t - static_cast<double>(t_spawn)) * 1e-6;
          } else {
            every = false;
          }
        }
        return every;
      },
      kFleetBound);
  if (!complete) {
    std::string report;
    for (const Robot& r : robots) {
      std::set<std::string> seen;
      for (const Event& e : find_events(r.watch->output(), "first")) {
        seen.insert(e.str("source"));
      }
      const std::string run_out = r.run->output();
      report += r.host + " sees " + std::to_string(seen.size()) + " of " + std::to_string(n) +
                "; its poise run ends: " + run_out.substr(run_out.size() > 400 ? run_out.size() - 400 : 0) +
                "\n";
    }
    FAIL() << "not every robot saw every estimate within the bound:\n" << report;
  }

  // CPU and bandwidth per robot over the window.
  std::vector<double> cpu0, bytes0;
  for (const Robot& r : robots) {
    cpu0.push_back(cpu_seconds(r.board->pid()) + cpu_seconds(r.run->pid()) +
                   cpu_seconds(r.watch->pid()));
    bytes0.push_back(eth0_bytes(lab, r.host));
  }
  const double server_bytes0 = eth0_bytes(lab, "server");
  const double server_cpu0 = cpu_seconds(server.pid());
  const int64_t w0 = monotonic_ns();
  testing::sleep_ms(kWindowMs);
  const double window_s = static_cast<double>(monotonic_ns() - w0) * 1e-9;
  std::vector<double> cpu_pct, kbps;
  for (size_t k = 0; k < robots.size(); ++k) {
    const Robot& r = robots[k];
    const double cpu1 = cpu_seconds(r.board->pid()) + cpu_seconds(r.run->pid()) +
                        cpu_seconds(r.watch->pid());
    cpu_pct.push_back(100.0 * (cpu1 - cpu0[k]) / window_s);
    kbps.push_back((eth0_bytes(lab, r.host) - bytes0[k]) * 8e-3 / window_s);
  }
  const double server_kbps = (eth0_bytes(lab, "server") - server_bytes0) * 8e-3 / window_s;
  const double server_cpu = 100.0 * (cpu_seconds(server.pid()) - server_cpu0) / window_s;
  std::ifstream loadavg("/proc/loadavg");
  std::string load;
  std::getline(loadavg, load);
  std::printf("[figure] fleet %d robots, %s Hz IMU, discovery server: spawn of all %d processes "
              "took %.1f s; first spawn -> every robot sees every estimate: median %.1f s, last "
              "%.1f s (%.1f s after the last spawn)\n",
              n, kImuRateHz, 3 * n, static_cast<double>(t_started - t_spawn) * 1e-9,
              median(last_ms) * 1e-3, *std::max_element(last_ms.begin(), last_ms.end()) * 1e-3,
              *std::max_element(last_ms.begin(), last_ms.end()) * 1e-3 -
                  static_cast<double>(t_started - t_spawn) * 1e-9);
  std::printf("[figure] fleet %d robots: per robot (board + driver/filter + watcher) CPU median "
              "%.1f %% max %.1f %% of one core; eth0 in+out median %.0f kbit/s max %.0f kbit/s; "
              "server %.1f %% CPU, %.0f kbit/s; loadavg %s\n",
              n, median(cpu_pct), *std::max_element(cpu_pct.begin(), cpu_pct.end()),
              median(kbps), *std::max_element(kbps.begin(), kbps.end()), server_cpu, server_kbps,
              load.c_str());
  for (Robot& r : robots) {
    EXPECT_TRUE(find_events(r.watch->output(), "error").empty()) << r.watch->output();
  }
}

INSTANTIATE_TEST_SUITE_P(Fleet, FleetFigure, ::testing::Values(10, 20),
                         [](const auto& param_info) {
                           return std::to_string(param_info.param) + "_robots";
                         });

}  // namespace
}  // namespace poise::nettest
