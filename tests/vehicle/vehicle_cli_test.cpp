// `poise sim vehicle` through its CLI module (no full `poise` build needed).
#include "poise/cli/common.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace poise::cli {
void register_vehicle_cli(CLI::App& app);
}

namespace {

std::string run_cli(std::vector<const char*> args) {
  CLI::App app{"poise"};
  poise::cli::register_vehicle_cli(app);
  args.insert(args.begin(), "poise");
  ::testing::internal::CaptureStdout();
  app.parse(static_cast<int>(args.size()), args.data());
  return ::testing::internal::GetCapturedStdout();
}

TEST(VehicleCli, JsonHasTheThreeEstimators) {
  const std::string out = run_cli({"sim", "vehicle", "--case", "double_lane_change", "--json"});
  EXPECT_EQ(out.front(), '{');
  EXPECT_EQ(out.find('\n'), out.size() - 1);
  for (const char* key : {"\"triad\":", "\"ekf\":", "\"switched\":", "\"roll_deg\":", "\"yaw_deg\":"}) {
    EXPECT_NE(out.find(key), std::string::npos) << key;
  }
}

// The --json output is JSON a parser accepts (undefined figures are null, never "-nan").
TEST(VehicleCli, JsonParses) {
  const std::string out = run_cli({"sim", "vehicle", "--case", "double_lane_change", "--json"});
  EXPECT_EQ(out.find("nan"), std::string::npos) << out;
  nlohmann::json j;
  ASSERT_NO_THROW(j = nlohmann::json::parse(out)) << out;
  EXPECT_EQ(j["switched"]["bank_samples"], 0);
}

TEST(VehicleCli, TextShowsTheBankFigure) {
  const std::string out = run_cli({"sim", "vehicle", "--case", "bank_20deg"});
  EXPECT_NE(out.find("mean roll err on the bank"), std::string::npos);
  EXPECT_NE(out.find("switched"), std::string::npos);
}

TEST(VehicleCli, BenchPrintsCpuAndWallFigures) {
  const std::string out = run_cli({"bench", "vehicle", "--samples", "2000", "--mode", "ekf"});
  EXPECT_NE(out.find("vehicle ekf:"), std::string::npos);
  EXPECT_NE(out.find("ns/sample cpu"), std::string::npos);
}

TEST(VehicleCli, UnknownCaseIsAUsageError) {
  EXPECT_THROW(run_cli({"sim", "vehicle", "--case", "moon"}), CLI::ValidationError);
  ::testing::internal::GetCapturedStdout();
  EXPECT_THROW(run_cli({"sim", "vehicle", "--help"}), CLI::CallForHelp);
  ::testing::internal::GetCapturedStdout();
}

}  // namespace
