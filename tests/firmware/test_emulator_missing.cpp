// Built instead of test_emulated_board.cpp when libsimavr-dev is missing: fails under CI=true.
#include <gtest/gtest.h>

#include "poise/testing/testing.h"

TEST(EmulatedGy87, GivenNoSimavrThenTheEmulationCannotRun) {
  POISE_SKIP("libsimavr-dev / libelf-dev not installed (tools/setup.sh installs them)");
}
