// `poise bench latency` end to end (short run): it prints every row with samples in each path.
// Figures are not asserted (a loaded 2-core CI machine makes them meaningless); the counts are.
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <regex>
#include <string>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;

TEST(BenchLatency, ShortRunPrintsPipelineHopPtyAndCpuRowsWithSamples) {
  DomainLease domain;
  const auto r = run({bin("poise"), "bench", "latency", "--domain", std::to_string(domain.id()), "--rates", "200",
                      "--duration", "1", "--window", "0.5"},
                     150s);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // rate row: pipeline p50/p99/max | hop p50/p99/max | ratio | rounds | CPU
  const std::regex rate_row(R"(\n\s+200 \|\s+[0-9.]+ /\s+[0-9.]+ /\s+[0-9.]+ \|\s+[0-9.]+ /\s+[0-9.]+ /\s+[0-9.]+ \|\s+[0-9.]+ \|)");
  EXPECT_TRUE(std::regex_search(r.output, rate_row)) << r.output;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.output, m, std::regex(R"(samples \|\s+([0-9]+) \|\s+([0-9]+) \|)"))) << r.output;
  // 1 s of each path at 200 Hz: about 200 samples each (the first line after each idle window
  // re-anchors the filter's time and gives no estimate)
  EXPECT_GT(std::stoi(m[1]), 150) << r.output;
  EXPECT_GT(std::stoi(m[2]), 150) << r.output;
  EXPECT_NE(r.output.find("pty only |"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("CPU at 1 kHz"), std::string::npos) << r.output;
}

TEST(BenchLatency, BadOptionIsAUsageError) {
  const auto r = run({bin("poise"), "bench", "latency", "--window", "0"}, 30s);
  EXPECT_EQ(r.exit_code, 2) << r.output;
}

}  // namespace
}  // namespace poise::testing
