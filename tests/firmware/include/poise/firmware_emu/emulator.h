// The GY-87 on an emulated Arduino Uno: the firmware's AVR binary (the same ELF `make` builds
// for the board) runs on simavr (ATmega328P, 16 MHz) with the sensor models of sensors.h on its
// TWI bus and its UART on a pseudo-terminal (PtyLink: what `poise imu --port` opens).
//
// Time: emulated time starts at power-on (0) and advances with the CPU's cycles. The run is
// paced against CLOCK_MONOTONIC (`speed` emulated seconds per host second; 0: as fast as the
// host can) and the crystal can be off by `crystal_ppm` (the emulated clock then runs that much
// fast against the host: what the driver's clock model must measure as the sensor's drift).
#pragma once

#include "poise/firmware_emu/sensors.h"

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

struct avr_irq_t;  // simavr (C)

namespace poise::firmware_emu {

enum class MagVariant { kHmc5883l, kQmc5883l, kNone, kUnknownAt0x2C };
const char* to_string(MagVariant v);

struct NackWindow {
  std::string device;  ///< "MPU6050", "HMC5883L", "QMC5883L", "BMP180"
  double from_s = 0.0;
  double to_s = 0.0;   ///< emulated seconds since power-on
};

struct EmulatorOptions {
  std::string elf;               ///< the firmware (avr-gcc ELF for the ATmega328P)
  std::string link;              ///< pty symlink for `poise imu --port`; empty: no pty
  MagVariant mag = MagVariant::kHmc5883l;
  std::string scenario = "moving";  ///< Motion scenario (sensors.h)
  uint64_t seed = 1;
  double speed = 1.0;            ///< emulated s per host s (0: unpaced)
  double crystal_ppm = 0.0;      ///< the board's clock runs this much fast against the host
  bool reset_on_open = true;     ///< an Uno resets when the port is opened (DTR)
  std::vector<NackWindow> nack_windows;
};

/// One `$` line the firmware sent, with what the sensors held when it went out: the values a
/// correct firmware reports in it (SI, body frame).
struct LineRecord {
  int boot = 0;               ///< 0 at power-on, +1 per reset
  bool delivered = false;     ///< every byte reached a reader of the pty
  bool lost = false;          ///< some byte was dropped (no reader, or the reader fell behind)
  bool complete = false;      ///< its \n was sent (seq and t_us are parsed)
  bool info = false;          ///< a $INF line (sensor info, no sample): lines() leaves it out
  std::string text;           ///< the line without \r\n
  uint32_t seq = 0;           ///< parsed from the line
  uint32_t t_us = 0;          ///< parsed from the line (the firmware's micros())
  int64_t sent_ns = 0;        ///< emulated time of its first byte on the UART
  int64_t written_host_ns = 0;  ///< CLOCK_MONOTONIC when its last bytes went to the pty
  DataRead imu;               ///< the MPU6050 burst read before it (accel, gyro, temperature)
  bool has_mag = false;       ///< a magnetometer reading stands: read since the boot and since the
                              ///< last NACK, not an overflow
  DataRead mag;
  bool has_pressure = false;  ///< a pressure result read since the boot and the last NACK
  DataRead pressure;
};

class Gy87Emulator {
 public:
  explicit Gy87Emulator(EmulatorOptions options);  ///< throws std::runtime_error
  ~Gy87Emulator();
  Gy87Emulator(const Gy87Emulator&) = delete;
  Gy87Emulator& operator=(const Gy87Emulator&) = delete;

  /// Runs for `seconds` of emulated time (or until stop()).
  void run_for(double seconds);
  void stop() { stop_ = true; }
  /// Resets the AVR alone (the sensors keep power and state), as DTR does.
  void reset_board();

  [[nodiscard]] int64_t now_ns() const;
  /// Some process has the pty open (call while the board is not running in another thread).
  [[nodiscard]] bool has_reader() const;
  /// Copies, safe while another thread runs the board.
  [[nodiscard]] std::vector<LineRecord> lines() const;
  [[nodiscard]] std::string uart_text() const;  ///< every byte the firmware sent
  [[nodiscard]] std::vector<Violation> violations() const;
  [[nodiscard]] uint64_t nacks(const std::string& device) const;
  /// Most stack + heap the firmware used (bytes of SRAM above .data + .bss ever written).
  [[nodiscard]] int stack_peak_bytes() const;
  [[nodiscard]] int static_ram_bytes() const { return static_ram_; }
  [[nodiscard]] int boots() const { return boot_; }
  [[nodiscard]] double host_seconds() const;  ///< host time spent in run_for()

 private:
  struct Sim;
  void step_chunk();
  void on_uart_byte(uint8_t byte);
  void on_twi(uint32_t value);
  void paint_stack();
  void measure_stack();
  static void uart_hook(::avr_irq_t* irq, uint32_t value, void* param);
  static void twi_hook(::avr_irq_t* irq, uint32_t value, void* param);

  EmulatorOptions opt_;
  std::unique_ptr<Sim> sim_;
  Motion motion_;
  Mpu6050 mpu_;
  std::unique_ptr<RegisterDevice> mag_;
  Bmp180 bmp_;
  I2cBus bus_;
  std::atomic<bool> stop_{false};
  int boot_ = 0;
  uint64_t cycles_done_ = 0;  ///< cycles of earlier boots
  uint64_t boot_cycle0_ = 0;  ///< the simavr cycle counter at the start of this boot
  int static_ram_ = 0;
  int stack_peak_ = 0;
  int64_t host_start_ns_ = -1;
  int64_t emu_start_ns_ = 0;
  int64_t boot_start_ns_ = 0;  ///< emulated time of the last reset (0: power-on)
  double host_seconds_ = 0.0;
  bool had_reader_ = false;
  std::string pending_;        ///< UART bytes not yet written to the pty
  std::vector<std::size_t> pending_lines_;  ///< indices of lines whose '\n' is in pending_
  bool in_line_ = false;
  bool line_ended_ = false;    ///< a line's \n was sent in this step
  mutable std::mutex mu_;
  std::string uart_;
  std::vector<LineRecord> lines_;
};

}  // namespace poise::firmware_emu
