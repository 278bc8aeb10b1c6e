// Host files that work wherever they are (docs/DEPLOY.md "Host files"): a shipped host file copied
// to another directory (as to /etc/poise) still finds the shipped filter and driver files its
// `../filters/...` and `../drivers/...` name, through the shipped configuration beside the
// executable (build/share/poise here, <prefix>/share/poise installed); what is found nowhere is an
// error naming the real paths tried, never a source-tree path.
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include <unistd.h>

namespace poise::testing {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

constexpr auto kRunTimeout = 60s;

/// A directory standing for /etc/poise, removed at the end of the test.
class EtcDir {
 public:
  EtcDir() : path_(fs::temp_directory_path() / ("poise_etc_" + std::to_string(::getpid())) / "poise") {
    fs::remove_all(path_.parent_path());
    fs::create_directories(path_);
  }
  ~EtcDir() { fs::remove_all(path_.parent_path()); }
  EtcDir(const EtcDir&) = delete;
  EtcDir& operator=(const EtcDir&) = delete;
  [[nodiscard]] const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

/// The shipped configuration the build tree's poise sees (build/bin/../share/poise).
fs::path shipped_dir() { return (fs::path(bin("poise")).parent_path() / ".." / "share" / "poise").lexically_normal(); }

}  // namespace

TEST(HostPaths, GivenTheShippedRobotHostCopiedToAnotherDirectoryWhenRunThenItsFilterAndDriverFilesComeFromTheShippedConfiguration) {
  ASSERT_TRUE(fs::is_directory(shipped_dir() / "hosts")) << shipped_dir() << " (made at configure time)";
  EtcDir etc;
  const std::string text = read_file(source_path("config/hosts/robot.yaml"));
  ASSERT_NE(text.find("config_file: ../drivers/imu.yaml"), std::string::npos) << "the shipped file changed";
  ASSERT_NE(text.find("filter_file: ../filters/altitude.yaml"), std::string::npos) << "the shipped file changed";
  fs::copy_file(source_path("config/hosts/robot.yaml"), etc.path() / "robot.yaml");
  ASSERT_FALSE(fs::exists(etc.path() / "../drivers/imu.yaml"));
  DomainLease domain;
  // The serial port need not exist: the driver waits for it (it may be plugged in later).
  const RunResult r = run({bin("poise"), "run", (etc.path() / "robot.yaml").string(), "--duration", "1",
                           "--domain", std::to_string(domain.id()), "--set", "imu0.port=/nonexistent/ttyACM9"},
                          kRunTimeout);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("3 component(s) running"), std::string::npos) << r.output;
}

TEST(HostPaths, GivenACopiedHostNamingAFileFoundNowhereWhenRunThenTheErrorNamesTheRealPathsTried) {
  EtcDir etc;
  std::ofstream(etc.path() / "robot.yaml")
      << "components:\n  - {type: altitude, name: alt, params: {filter_file: ../filters/none.yaml}}\n";
  const RunResult r = run({bin("poise"), "run", (etc.path() / "robot.yaml").string(), "--duration", "1"}, kRunTimeout);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  const std::string beside = (etc.path().parent_path() / "filters/none.yaml").string();
  const std::string shipped = (shipped_dir() / "filters/none.yaml").string();
  EXPECT_NE(r.output.find("params.filter_file '../filters/none.yaml' not found at " + beside +
                          " (beside the host file) nor at " + shipped + " (beside the shipped host files)"),
            std::string::npos)
      << r.output;
}

TEST(HostPaths, GivenAnImuDriverConfigThatDoesNotExistWhenRunThenTheErrorNamesTheShippedExampleByItsRealPath) {
  EtcDir etc;
  const std::string missing = (etc.path() / "imu.yaml").string();
  std::ofstream(etc.path() / "robot.yaml") << "components:\n  - {type: imu_driver, name: imu0, params: {port: "
                                              "/nonexistent/ttyACM9, config_file: " << missing << "}}\n";
  const RunResult r = run({bin("poise"), "run", (etc.path() / "robot.yaml").string(), "--duration", "1"}, kRunTimeout);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("config_file " + missing + " does not exist (start from " +
                          (shipped_dir() / "drivers/imu.yaml").string() + ", or run `poise calibrate imu`)"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("config/drivers"), std::string::npos) << "no source-tree path: " << r.output;
}

}  // namespace poise::testing
