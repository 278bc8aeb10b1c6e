// The IMU commands as processes: `poise sim-imu` -> `poise imu` -> DDS subscriber (this test),
// with faults and a disconnect; help and error conventions.
#include <gtest/gtest.h>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include "poise/dds/convert.h"
#include "poise/dds/participant.h"
#include "poise/imu/config.h"
#include "poise/testing/testing.h"

#include <Eigen/Core>

namespace poise::imu {
namespace {

using namespace std::chrono_literals;
using poise::testing::Child;
using poise::testing::run;

/// The executable under test: `poise` (POISE_IMU_TEST_BIN may point at poise_imu_dev).
std::string poise_bin() {
  const char* env = std::getenv("POISE_IMU_TEST_BIN");
  return env != nullptr && *env != '\0' ? env : poise::testing::bin("poise");
}

std::string temp_path(const std::string& tag) {
  return ::testing::TempDir() + "poise-imu-cli-" + tag + "-" + std::to_string(::getpid());
}

TEST(ImuCli, HelpWorksForEveryCommand) {
  for (const auto& args : std::vector<std::vector<std::string>>{
           {"imu", "--help"}, {"sim-imu", "--help"}, {"calibrate", "imu", "--help"}, {"bench", "imu", "--help"}}) {
    std::vector<std::string> argv{poise_bin()};
    argv.insert(argv.end(), args.begin(), args.end());
    const auto r = run(argv, 20s);
    EXPECT_EQ(r.exit_code, 0) << args[0] << ": " << r.output;
    EXPECT_NE(r.output.find("Usage"), std::string::npos) << r.output;
  }
}

TEST(ImuCli, UsageAndSetupErrorsAreClear) {
  auto r = run({poise_bin(), "imu", "--port", "/tmp/x", "--baud", "12345"}, 20s);
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = run({poise_bin(), "sim-imu", "--link", temp_path("bad"), "--faults", "bogus=1"}, 20s);
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("unknown key 'bogus'"), std::string::npos) << r.output;
  const std::string bad_config = temp_path("bad.yaml");
  std::ofstream(bad_config) << "calibration: {mag_soft_iron: [[1,0,0],[0,1,0],[0,0,0]]}\n";
  r = run({poise_bin(), "imu", "--port", "/tmp/x", "--config", bad_config, "--duration", "1"}, 20s);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("mag_soft_iron"), std::string::npos) << r.output;
  ::unlink(bad_config.c_str());
}

uint64_t stat_of(const std::string& output, const std::string& key) {
  const std::regex re(key + ": ([0-9]+)");
  std::smatch m;
  return std::regex_search(output, m, re) ? std::stoull(m[1].str()) : ~0ull;
}

/// The final line `poise imu` prints when it stops: "NAME: final: R samples read (L lines, B bytes),
/// P published, X rejected: reason n, reason n; G lost (seq gaps); dropped S stale, F queue full, A at
/// stop, W write failures; D disconnects".
struct FinalCounts {
  bool found = false;
  uint64_t read = 0;
  uint64_t lines = 0;
  uint64_t published = 0;
  uint64_t rejected = 0;
  std::map<std::string, uint64_t> reasons;
  uint64_t dropped = 0;  ///< stale + queue full + at stop + write failures
  [[nodiscard]] uint64_t reason(const std::string& name) const {
    const auto it = reasons.find(name);
    return it == reasons.end() ? 0 : it->second;
  }
};

FinalCounts final_counts_of(const std::string& output) {
  static const std::regex line_re(
      R"((\S+): final: (\d+) samples read \((\d+) lines, \d+ bytes\), (\d+) published, (\d+) rejected(: [^;]*)?; )"
      R"((\d+) lost \(seq gaps\); dropped (\d+) stale, (\d+) queue full, (\d+) at stop, (\d+) write failures)");
  FinalCounts c;
  std::smatch m;
  if (!std::regex_search(output, m, line_re)) {
    return c;
  }
  c.found = true;
  c.read = std::stoull(m[2].str());
  c.lines = std::stoull(m[3].str());
  c.published = std::stoull(m[4].str());
  c.rejected = std::stoull(m[5].str());
  const std::string reasons = m[6].str();
  static const std::regex reason_re(R"(([a-z_]+) (\d+))");
  for (auto it = std::sregex_iterator(reasons.begin(), reasons.end(), reason_re); it != std::sregex_iterator(); ++it) {
    c.reasons[(*it)[1].str()] = std::stoull((*it)[2].str());
  }
  for (int i = 8; i <= 11; ++i) {
    c.dropped += std::stoull(m[i].str());
  }
  return c;
}

TEST(ImuCli, SimImuThroughImuToASubscriberWithFaultsAndADisconnect) {
  // GIVEN `poise imu` waiting for a device that `poise sim-imu` then provides, with bit flips,
  // garbage and a 0.3 s disconnect (board reboot) in the middle
  poise::testing::DomainLease domain;
  const std::string link = temp_path("link");
  const std::string d = std::to_string(domain.id());
  std::mutex mu;
  std::map<std::string, uint64_t> counters;
  uint64_t received = 0;
  // The driver publishes the board's seq and drops duplicates and out-of-order lines, so seq goes
  // back only when the board restarted (it counts from 0 again after the reconnect). How much
  // came before depends on the driver's reopen backoff (up to reconnect_max_s = 2 s while it
  // waited for the device, so as little as 1 s of the 3 s before the disconnect): not asserted.
  bool have_seq = false;
  uint32_t last_seq = 0;
  uint32_t max_seq_before_restart = 0;
  uint64_t received_before_restart = 0;
  uint64_t received_after_restart = 0;
  int restarts = 0;
  dds::Participant participant({domain.id(), "", "", "imu cli test"});
  dds::Reader<msg::FilterDiagnosticsPubSubType> diag(
      participant, "diagnostics", [&](const msg::FilterDiagnostics& m, const auto&) {
        if (m.component_name().to_string() != "imu_driver") return;
        std::lock_guard<std::mutex> lock(mu);
        for (const auto& c : m.counters()) counters[c.name().to_string()] = c.value();
      });
  dds::Reader<msg::ImuSamplePubSubType> imu(participant, "imu", [&](const msg::ImuSample& m, const auto&) {
    std::lock_guard<std::mutex> lock(mu);
    ++received;
    const uint32_t seq = m.header().seq();
    if (have_seq && seq < last_seq) ++restarts;
    have_seq = true;
    last_seq = seq;
    if (restarts == 0) {
      ++received_before_restart;
      max_seq_before_restart = seq;
    } else {
      ++received_after_restart;
    }
  });
  Child driver({poise_bin(), "imu", "--port", link, "--domain", d, "--status-period", "1"});
  ASSERT_TRUE(imu.wait_for_writers(1, 20s)) << driver.output();
  // one disconnect at 3 s, then 2.6 s of data: a loaded machine may take a while to reopen the device
  Child sim({poise_bin(), "sim-imu", "--link", link, "--rate", "200", "--duration", "5.9",
             "--faults", "flip=0.03,garbage=0.03,disconnect=3:0.3,seed=4"});
  // WHEN the simulated device finishes
  const auto sim_exit = sim.wait_for(30s);
  ASSERT_TRUE(sim_exit.has_value()) << sim.output();
  EXPECT_EQ(*sim_exit, 0) << sim.output();
  EXPECT_NE(::access(link.c_str(), F_OK), 0) << "sim-imu must remove its symlink";
  const std::string out = sim.output();
  const uint64_t flips = stat_of(out, "fault_flip");
  const uint64_t garbage = stat_of(out, "fault_garbage");
  ASSERT_NE(flips, ~0ull) << out;
  ASSERT_GT(flips + garbage, 0u) << out;
  EXPECT_EQ(stat_of(out, "disconnects"), 1u) << out;
  // THEN the driver counted every injected fault, reconnected by itself and kept publishing
  const auto counter = [&](const std::string& k) {
    std::lock_guard<std::mutex> lock(mu);
    const auto it = counters.find(k);
    return it == counters.end() ? ~0ull : it->second;
  };
  EXPECT_TRUE(poise::testing::wait_until(
      [&] { return counter("rejected_checksum_mismatch") == flips && counter("rejected_garbage") == garbage; },
      20s))
      << "flips " << flips << " vs " << counter("rejected_checksum_mismatch") << ", garbage " << garbage
      << " vs " << counter("rejected_garbage") << "\n" << driver.output();
  EXPECT_GE(counter("connects"), 2u) << driver.output();
  {
    std::lock_guard<std::mutex> lock(mu);
    EXPECT_GT(received, 300u);
    EXPECT_GT(received_before_restart, 0u) << driver.output();
    EXPECT_GE(restarts, 1) << "no sample after the reconnect; max seq before " << max_seq_before_restart
                           << "\n" << driver.output();
    // 2.6 s of data after the reconnect at 200 Hz (520 lines); the driver retries from 0.1 s,
    // doubling: it reopens within 0.7 s of the 0.3 s disconnect, leaving >= 1.6 s (320 lines).
    // 100 (0.5 s) leaves room for a loaded machine.
    EXPECT_GE(received_after_restart, 100u) << "publishing must resume after the reconnect; max seq before "
                                            << max_seq_before_restart << "\n" << driver.output();
  }
  // AND the driver stops cleanly on SIGINT, printing its final counts: the same rejections by reason
  driver.signal(SIGINT);
  const auto drv_exit = driver.wait_for(15s);
  ASSERT_TRUE(drv_exit.has_value()) << driver.output();
  EXPECT_EQ(*drv_exit, 0) << driver.output();
  const FinalCounts final_counts = final_counts_of(driver.output());
  ASSERT_TRUE(final_counts.found) << driver.output();
  EXPECT_EQ(final_counts.reason("checksum_mismatch"), flips) << driver.output();
  EXPECT_EQ(final_counts.reason("garbage"), garbage) << driver.output();
}

// GIVEN `poise imu` reading `poise sim-imu` with bit flips and garbage
// WHEN it stops at the end of --duration, or on SIGTERM
// THEN it prints its final counts (stdout, with --quiet too): the rejections by reason equal the
//      faults the simulator injected (its own counts, the oracle), every sample read is published or
//      counted dropped, and no more samples are read than the simulator wrote good lines
TEST(ImuCli, GivenFaultsWhenImuStopsByDurationOrSigtermThenItPrintsItsFinalCountsByReason) {
  poise::testing::DomainLease domain;
  const std::string d = std::to_string(domain.id());
  for (const bool by_signal : {false, true}) {
    SCOPED_TRACE(by_signal ? "SIGTERM" : "--duration");
    const std::string link = temp_path(by_signal ? "final-term" : "final-duration");
    std::vector<std::string> imu_args{poise_bin(), "imu", "--port", link, "--domain", d, "--quiet"};
    if (!by_signal) {
      imu_args.insert(imu_args.end(), {"--duration", "12"});
    }
    Child driver(imu_args);
    Child sim({poise_bin(), "sim-imu", "--link", link, "--rate", "200", "--duration", "3", "--faults",
               "flip=0.04,garbage=0.04,seed=11"});
    const auto sim_exit = sim.wait_for(30s);
    ASSERT_TRUE(sim_exit.has_value()) << sim.output();
    ASSERT_EQ(*sim_exit, 0) << sim.output();
    const std::string sim_out = sim.output();
    const uint64_t written = stat_of(sim_out, "lines_written");
    const uint64_t flips = stat_of(sim_out, "fault_flip");
    const uint64_t garbage = stat_of(sim_out, "fault_garbage");
    ASSERT_NE(written, ~0ull) << sim_out;
    ASSERT_GT(flips, 0u) << sim_out;
    ASSERT_GT(garbage, 0u) << sim_out;
    if (by_signal) {
      std::this_thread::sleep_for(500ms);  // the driver reads what is left in the pty
      driver.signal(SIGTERM);
    }
    const auto code = driver.wait_for(30s);
    ASSERT_TRUE(code.has_value()) << driver.output();
    EXPECT_EQ(*code, 0) << driver.output();
    const FinalCounts c = final_counts_of(driver.output());
    ASSERT_TRUE(c.found) << driver.output();
    EXPECT_EQ(c.reason("checksum_mismatch"), flips) << driver.output();
    EXPECT_EQ(c.reason("garbage"), garbage) << driver.output();
    uint64_t by_reason = 0;
    for (const auto& [reason, n] : c.reasons) {
      by_reason += n;
    }
    EXPECT_EQ(c.rejected, by_reason) << driver.output();
    EXPECT_GT(c.read, 0u) << driver.output();
    EXPECT_LE(c.read, written - flips) << "a corrupted line is never a sample\n" << driver.output();
    EXPECT_EQ(c.published + c.dropped, c.read) << "every sample read is published or counted dropped\n"
                                               << driver.output();
  }
}

TEST(ImuCli, CalibrateRecoversAKnownDistortionFromSimImu) {
  // GIVEN a simulated board (8 s still, then tumbling) with gyro bias b_g (the simulator's) and a
  // magnetometer seen through A plus offset b, streaming 10x faster than real time
  const std::string link = temp_path("cal");
  const std::string out = temp_path("cal.yaml");
  const Eigen::Vector3d kGyroBias = Eigen::Vector3d(0.3, -0.2, 0.25) * 3.14159265358979 / 180.0;
  const Eigen::Vector3d kHardIron(14.0, -31.0, 47.0);
  Eigen::Matrix3d a;
  a << 1.15, 0.06, -0.03, 0.06, 0.88, 0.04, -0.03, 0.04, 1.02;
  // WHEN `poise calibrate imu` reads it (started first: the board resets when the port opens)
  Child cal({poise_bin(), "calibrate", "imu", "--port", link, "--output", out, "--still-s", "2",
             "--timeout", "60"});
  Child sim({poise_bin(), "sim-imu", "--link", link, "--scenario", "calibration", "--rate", "100",
             "--speed", "10", "--duration", "60", "--mag-hard-iron", "14,-31,47",
             "--mag-soft-iron", "1.15,0.06,-0.03,0.06,0.88,0.04,-0.03,0.04,1.02", "--quiet"});
  const auto code = cal.wait_for(90s);
  sim.signal(SIGINT);
  ASSERT_TRUE(code.has_value()) << cal.output();
  ASSERT_EQ(*code, 0) << cal.output();
  EXPECT_NE(cal.output().find("coverage"), std::string::npos) << "progress display";
  // THEN the YAML it wrote holds the bias, b and A^-1 (up to the field-magnitude scale)
  const DriverConfig c = load_driver_config(out);
  constexpr double kGyroBiasTolRps = 3e-4;
  constexpr double kHardIronTolUt = 0.5;
  constexpr double kShapeTol = 0.02;
  EXPECT_LT((c.calibration.gyro_bias_rps - kGyroBias).cwiseAbs().maxCoeff(), kGyroBiasTolRps)
      << c.calibration.gyro_bias_rps.transpose();
  EXPECT_LT((c.calibration.mag_hard_iron_ut - kHardIron).cwiseAbs().maxCoeff(), kHardIronTolUt)
      << c.calibration.mag_hard_iron_ut.transpose();
  const Eigen::Matrix3d wa = c.calibration.mag_soft_iron * a;  // = s I for the right W
  EXPECT_LT((wa / wa.trace() * 3.0 - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), kShapeTol)
      << wa;
  ::unlink(out.c_str());
}

}  // namespace
}  // namespace poise::imu
