// gy87_emu: the GY-87 firmware on the emulated Uno by hand (docs/FIRMWARE.md). Creates the pty
// symlink, runs the board paced to the host clock and prints what the firmware did:
//   gy87_emu --link /tmp/gy87 --duration 10 &  poise imu --port /tmp/gy87
#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "poise/firmware_emu/emulator.h"

namespace {
poise::firmware_emu::Gy87Emulator* g_board = nullptr;
void on_signal(int) {
  if (g_board != nullptr) g_board->stop();
}
}  // namespace

int main(int argc, char** argv) {
  using poise::firmware_emu::MagVariant;
  CLI::App app{"The GY-87 firmware (AVR binary) on simavr with datasheet models of its sensors"};
  poise::firmware_emu::EmulatorOptions o;
  o.elf = POISE_GY87_ELF;
  double duration_s = 10.0;
  std::string mag = "hmc5883l";
  std::vector<std::string> nacks;
  bool no_reset = false;
  std::string dump;
  app.add_option("--elf", o.elf, "firmware ELF")->capture_default_str();
  app.add_option("--link", o.link, "pty symlink for poise imu --port (none: no pty)");
  app.add_option("--mag", mag, "magnetometer: hmc5883l | qmc5883l | none | unknown")->capture_default_str();
  app.add_option("--scenario", o.scenario, "motion: moving | a poise sim scenario")->capture_default_str();
  app.add_option("--seed", o.seed, "motion seed")->capture_default_str();
  app.add_option("--duration", duration_s, "emulated seconds")->capture_default_str();
  app.add_option("--speed", o.speed, "emulated s per host s (0: as fast as possible)")->capture_default_str();
  app.add_option("--crystal-ppm", o.crystal_ppm, "board clock error against the host, ppm");
  app.add_option("--nack", nacks, "DEVICE:FROM_S:TO_S (MPU6050, HMC5883L, QMC5883L, BMP180)");
  app.add_flag("--no-reset-on-open", no_reset, "the board does not reset when the port is opened");
  app.add_option("--lines-csv", dump, "write boot,seq,t_us,read_ns,sent_ns,delivered,has_mag,has_pressure,host_ns,text per line");
  CLI11_PARSE(app, argc, argv);
  o.reset_on_open = !no_reset;
  if (mag == "hmc5883l") o.mag = MagVariant::kHmc5883l;
  else if (mag == "qmc5883l") o.mag = MagVariant::kQmc5883l;
  else if (mag == "none") o.mag = MagVariant::kNone;
  else if (mag == "unknown") o.mag = MagVariant::kUnknownAt0x2C;
  else {
    std::fprintf(stderr, "gy87_emu: unknown --mag '%s'\n", mag.c_str());
    return 2;
  }
  for (const std::string& n : nacks) {
    poise::firmware_emu::NackWindow w;
    char dev[32] = {};
    if (std::sscanf(n.c_str(), "%31[^:]:%lf:%lf", dev, &w.from_s, &w.to_s) != 3) {
      std::fprintf(stderr, "gy87_emu: --nack wants DEVICE:FROM_S:TO_S, got '%s'\n", n.c_str());
      return 2;
    }
    w.device = dev;
    o.nack_windows.push_back(w);
  }
  try {
    poise::firmware_emu::Gy87Emulator board(o);
    g_board = &board;
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    board.run_for(duration_s);
    g_board = nullptr;
    std::size_t lines = 0;
    for (const auto& r : board.lines()) lines += r.delivered ? 1 : 0;
    std::printf("emulated_s: %.3f\nhost_s: %.3f\nlines: %zu\nlines_delivered: %zu\nboots: %d\n"
                "static_ram_bytes: %d\nstack_peak_bytes: %d\nviolations: %zu\n",
                static_cast<double>(board.now_ns()) * 1e-9, board.host_seconds(), board.lines().size(), lines,
                board.boots() + 1, board.static_ram_bytes(), board.stack_peak_bytes(), board.violations().size());
    if (!dump.empty()) {
      std::FILE* f = std::fopen(dump.c_str(), "w");
      if (f == nullptr) throw std::runtime_error("cannot write " + dump);
      std::fprintf(f, "boot,seq,t_us,read_ns,sent_ns,delivered,has_mag,has_pressure,host_ns,text\n");
      for (const auto& r : board.lines()) {
        std::fprintf(f, "%d,%u,%u,%lld,%lld,%d,%d,%d,%lld,\"%s\"\n", r.boot, r.seq, r.t_us,
                     static_cast<long long>(r.imu.t_ns), static_cast<long long>(r.sent_ns), r.delivered ? 1 : 0,
                     r.has_mag ? 1 : 0, r.has_pressure ? 1 : 0,
                     static_cast<long long>(r.written_host_ns), r.text.c_str());
      }
      std::fclose(f);
    }
    for (const auto& v : board.violations()) {
      std::printf("  %s at %.3f ms: %s\n", v.device.c_str(), static_cast<double>(v.t_ns) * 1e-6, v.rule.c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gy87_emu: %s\n", e.what());
    return 1;
  }
  return 0;
}
