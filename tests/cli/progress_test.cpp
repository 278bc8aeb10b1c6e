// Progress of long work (poise/cli/progress.h), in simulated time: nothing for work under 2 s;
// past that one line redrawn in place on a terminal, a few plain lines otherwise.
#include "poise/cli/progress.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>
#include <string>

namespace poise::cli {
namespace {

constexpr double kStepS = 0.05;  // an update every 50 ms of (simulated) work

struct Run {
  std::string out;
};

// Work of `duration_s` with an update every kStepS, on a terminal or not.
Run work(double duration_s, bool terminal) {
  std::ostringstream os;
  double now = 100.0;
  Progress::Options o;
  o.out = &os;
  o.terminal = terminal ? 1 : 0;
  o.now_s = [&now] { return now; };
  o.ticker = false;
  const int steps = static_cast<int>(duration_s / kStepS);
  {
    Progress p("poise test", static_cast<uint64_t>(steps), o);
    for (int i = 0; i <= steps; ++i) {
      p.update(static_cast<uint64_t>(i), "step");
      now += kStepS;
    }
    now -= kStepS;
  }  // the destructor finishes
  return {os.str()};
}

TEST(Progress, WorkUnderTwoSecondsPrintsNothing) {
  EXPECT_EQ(work(1.9, true).out, "");
  EXPECT_EQ(work(1.9, false).out, "");
}

TEST(Progress, OnATerminalOneLineIsRedrawnInPlace) {
  const std::string out = work(10.0, true).out;
  ASSERT_FALSE(out.empty());
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;  // only the closing one
  EXPECT_EQ(out.back(), '\n');
  EXPECT_GT(std::count(out.begin(), out.end(), '\r'), 10) << out;  // redrawn, at most every 0.2 s
  EXPECT_LE(std::count(out.begin(), out.end(), '\r'), static_cast<long>(10.0 / kProgressRedrawS) + 2) << out;
  EXPECT_NE(out.find("done in 10.0 s"), std::string::npos) << out;
}

TEST(Progress, OtherwiseAFewPlainLines) {
  const std::string out = work(30.0, false).out;
  EXPECT_EQ(out.find('\r'), std::string::npos) << out;
  // first line at 2 s, then one every 10 s (12 s, 22 s), then the closing line
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 4) << out;
  EXPECT_EQ(out.rfind("poise test:   7 % (4", 0), 0U) << out;  // the first line at 2 s (about 40 of 600 steps)
  EXPECT_NE(out.find(", 2 s, step\n"), std::string::npos) << out;
}

}  // namespace
}  // namespace poise::cli
