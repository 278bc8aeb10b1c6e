// `poise sim altitude` through its CLI module (no full `poise` build needed).
#include "poise/cli/common.h"

#include <CLI/CLI.hpp>
#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace poise::cli {
void register_altitude_cli(CLI::App& app);
}

namespace {

std::string run_cli(std::vector<const char*> args) {
  CLI::App app{"poise"};
  poise::cli::register_altitude_cli(app);
  args.insert(args.begin(), "poise");
  ::testing::internal::CaptureStdout();
  app.parse(static_cast<int>(args.size()), args.data());
  return ::testing::internal::GetCapturedStdout();
}

TEST(AltitudeCli, JsonPrintsOneObjectWithBothRmse) {
  const std::string out = run_cli({"sim", "altitude", "--scenario", "random", "--method", "pi_cf_zupt",
                                   "--seed", "2", "--json"});
  EXPECT_EQ(out.front(), '{');
  EXPECT_EQ(out.find('\n'), out.size() - 1);  // one line
  EXPECT_NE(out.find("\"vertical_velocity_rmse_mps\":"), std::string::npos);
  EXPECT_NE(out.find("\"height_rmse_m\":"), std::string::npos);
  EXPECT_NE(out.find("\"method\":\"pi_cf_zupt\""), std::string::npos);
  EXPECT_NE(out.find("\"seed\":2"), std::string::npos);
}

TEST(AltitudeCli, TextNamesTheFigures) {
  const std::string out = run_cli({"sim", "altitude", "--scenario", "stairs_1_5m", "--method", "cf_zupt"});
  EXPECT_NE(out.find("vertical velocity RMSE"), std::string::npos);
  EXPECT_NE(out.find("height RMSE"), std::string::npos);
}

TEST(AltitudeCli, UnknownProfileOrMethodIsAUsageError) {
  EXPECT_THROW(run_cli({"sim", "altitude", "--scenario", "moon"}), CLI::ValidationError);
  ::testing::internal::GetCapturedStdout();
  EXPECT_THROW(run_cli({"sim", "altitude", "--method", "magic"}), CLI::ValidationError);
  ::testing::internal::GetCapturedStdout();
  EXPECT_THROW(run_cli({"sim", "altitude", "--help"}), CLI::CallForHelp);
  ::testing::internal::GetCapturedStdout();
}

TEST(AltitudeCli, BenchPrintsCpuAndWallFigures) {
  const std::string out = run_cli({"bench", "altitude", "--samples", "2000"});
  EXPECT_NE(out.find("ns/sample cpu"), std::string::npos);
  EXPECT_NE(out.find("ns/sample wall"), std::string::npos);
}

TEST(AltitudeCli, MissingConfigIsAnActionableError) {
  EXPECT_THROW(run_cli({"sim", "altitude", "--config", "/nonexistent/altitude.yaml"}),
               poise::cli::Error);
  ::testing::internal::GetCapturedStdout();
}

}  // namespace
