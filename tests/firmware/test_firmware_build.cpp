// The firmware as CI builds it for the Arduino Uno (Debian's arduino-mk, tools/firmware/gy87_poise/
// Makefile): its flash and static RAM within the stated budget. Prints the figures.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <regex>
#include <string>

#include "poise/testing/testing.h"

namespace {

using namespace std::chrono_literals;

// The Uno: 32768 B flash of which the bootloader keeps 512 B, 2048 B SRAM. Budget: half of the
// flash, and half of the SRAM for .data + .bss (the other half for the stack; the emulated runs
// measure its peak, test_firmware_emulated).
constexpr long kFlashBudgetBytes = 16384;
constexpr long kStaticRamBudgetBytes = 1024;

long section(const std::string& size_a, const std::string& name) {
  std::smatch m;
  const std::regex re("\\n\\" + name + "\\s+([0-9]+)\\s");
  return std::regex_search(size_a, m, re) ? std::stol(m[1].str()) : -1;
}

TEST(FirmwareBuild, GivenTheUnoBuildThenFlashAndStaticRamFitTheBudget) {
  if (!POISE_FIRMWARE_TOOLS) POISE_SKIP("arduino-mk / gcc-avr not installed (tools/setup.sh installs them)");
  ASSERT_EQ(::access(POISE_GY87_ELF, R_OK), 0) << POISE_GY87_ELF << " not built";
  const auto r = poise::testing::run({POISE_AVR_SIZE, "-A", POISE_GY87_ELF}, 30s);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const long text = section(r.output, ".text");
  const long data = section(r.output, ".data");
  const long bss = section(r.output, ".bss");
  ASSERT_GT(text, 0) << r.output;
  ASSERT_GE(data, 0) << r.output;
  ASSERT_GE(bss, 0) << r.output;
  const long flash = text + data;  // .data's initial values live in flash too
  const long ram = data + bss;
  std::printf("[ figures  ] gy87_poise for the Uno: flash %ld B (.text %ld + .data %ld) of budget %ld B "
              "(32256 B available), static RAM %ld B (.data %ld + .bss %ld) of budget %ld B (2048 B SRAM)\n",
              flash, text, data, kFlashBudgetBytes, ram, data, bss, kStaticRamBudgetBytes);
  EXPECT_LE(flash, kFlashBudgetBytes);
  EXPECT_LE(ram, kStaticRamBudgetBytes);
}

}  // namespace
