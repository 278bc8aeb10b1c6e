// The `poise demo` report as a user reads it (issue 34): with the simulator, each filter's error on
// its own chart, the selective EKF's position and path against the truth, and every figure
// defined; with real hardware (`--port`, here `poise sim-imu` standing in for the board, which
// publishes no truth), no simulated scenario named, no truth waited for, no error claimed.
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <signal.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;

bool has(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

std::string temp_dir(const std::string& tag) {
  const std::string dir = ::testing::TempDir() + "poise-demo-report-" + tag + "-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  return dir;
}

// GIVEN the simulated demo (IMU, synthetic camera, every filter) WHEN it has run THEN the report has
// the error chart (one panel per filter), the position chart and the path (the selective EKF's pose
// against truth/pose), a position table by episode, and says what latency and every error are.
TEST(DemoReport, GivenTheSimulatedDemoThenTheReportShowsEachFiltersErrorThePositionAndDefinesEveryFigure) {
  DomainLease domain;
  const std::string dir = temp_dir("sim");
  const auto r = run({bin("poise"), "demo", "--duration", "12", "--plain", "--domain", std::to_string(domain.id()),
                      "--out-dir", dir},
                     120s);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* png : {"error.png", "position.png", "path.png", "attitude.png", "disturbance.png"}) {
    EXPECT_TRUE(std::filesystem::exists(dir + "/" + png)) << png;
  }
  const std::string index = read_file(dir + "/index.html");
  EXPECT_TRUE(has(index, "scenario: tour")) << index;
  EXPECT_TRUE(has(index, "<h2>Position</h2>")) << index;
  EXPECT_TRUE(has(index, "<th>during tag lost [m RMS]</th>")) << index;
  EXPECT_TRUE(has(index, "<b>latency</b>: ")) << index;
  EXPECT_TRUE(has(index, "<b>attitude error</b>: ")) << index;
  EXPECT_TRUE(has(index, "<b>position error</b>: ")) << index;
  EXPECT_TRUE(has(r.output, "truth")) << "the dashboard shows the simulated truth\n" << r.output;
  std::filesystem::remove_all(dir);
}

// GIVEN `poise demo --port` on a serial device (poise sim-imu's pty: a board for the driver, and
// no truth on the domain) WHEN it runs THEN it neither names a simulated scenario nor waits for or
// shows a truth, draws no error chart, and says why there is no error.
TEST(DemoReport, GivenARealImuPortThenNoSimulatedScenarioNoTruthAndNoErrorIsClaimed) {
  DomainLease domain;
  const std::string dir = temp_dir("port");
  const std::string link = dir + "-imu";
  Child board({bin("poise"), "sim-imu", "--link", link, "--rate", "100", "--duration", "30"});
  ASSERT_TRUE(wait_until([&] { return std::filesystem::exists(link); }, 20s)) << board.output();
  const auto r = run({bin("poise"), "demo", "--port", link, "--duration", "6", "--plain", "--domain",
                      std::to_string(domain.id()), "--out-dir", dir},
                     120s);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string index = read_file(dir + "/index.html");
  EXPECT_FALSE(has(index, "scenario:")) << index;
  EXPECT_FALSE(has(index, "tour")) << index;
  EXPECT_TRUE(has(index, "real hardware: no simulated scenario, no truth")) << index;
  EXPECT_TRUE(has(index, "no error is computed")) << index;
  EXPECT_FALSE(has(index, "RMSE vs truth")) << index;
  EXPECT_FALSE(std::filesystem::exists(dir + "/error.png"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/attitude.png"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/position.png")) << "no camera, no truth: a held position is no chart";
  EXPECT_FALSE(has(r.output, "truth")) << "no truth row, no truth waited for\n" << r.output;
  board.signal(SIGINT);
  (void)board.wait_for(15s);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace poise::testing
