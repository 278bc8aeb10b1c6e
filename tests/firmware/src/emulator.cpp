#include "poise/firmware_emu/emulator.h"

#include "poise/imu/pty_link.h"

#include <avr_twi.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_io.h>
#include <sim_irq.h>

#include <time.h>

#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <stdexcept>

namespace poise::firmware_emu {
namespace {

constexpr uint32_t kCpuHz = 16'000'000;       // the Uno's crystal (F_CPU)
constexpr uint64_t kChunkCycles = kCpuHz / 1000;  // 1 ms of emulated time per pacing step
constexpr uint8_t kPaint = 0xA5;               // unused SRAM pattern (stack high-water mark)
constexpr int kRamStart = 0x100;               // ATmega328P: SRAM after the register file + I/O

int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void quiet_logger(avr_t* /*avr*/, const int level, const char* format, va_list ap) {
  if (level <= LOG_ERROR) std::vfprintf(stderr, format, ap);
}

}  // namespace

const char* to_string(MagVariant v) {
  switch (v) {
    case MagVariant::kHmc5883l: return "hmc5883l";
    case MagVariant::kQmc5883l: return "qmc5883l";
    case MagVariant::kNone: return "none";
    case MagVariant::kUnknownAt0x2C: return "unknown@0x2c";
  }
  return "?";
}

struct Gy87Emulator::Sim {
  avr_t* avr = nullptr;
  elf_firmware_t firmware{};
  avr_irq_t* twi_in = nullptr;
  std::unique_ptr<imu::PtyLink> pty;
  ~Sim() {
    if (avr != nullptr) avr_terminate(avr);
  }
};

Gy87Emulator::Gy87Emulator(EmulatorOptions options)
    : opt_(std::move(options)),
      sim_(std::make_unique<Sim>()),
      motion_(opt_.scenario, opt_.seed),
      mpu_(motion_),
      bmp_(motion_) {
  switch (opt_.mag) {
    case MagVariant::kHmc5883l: mag_ = std::make_unique<Hmc5883l>(motion_, mpu_); break;
    case MagVariant::kQmc5883l: mag_ = std::make_unique<Qmc5883l>(motion_, mpu_); break;
    case MagVariant::kUnknownAt0x2C: mag_ = std::make_unique<UnknownChip>(0x2C); break;
    case MagVariant::kNone: break;
  }
  bus_.attach(&mpu_);
  if (mag_) bus_.attach(mag_.get());
  bus_.attach(&bmp_);
  for (const NackWindow& w : opt_.nack_windows) {
    bool found = false;
    for (I2cDevice* d : bus_.devices()) {
      if (d->name() == w.device) {
        d->add_nack_window(static_cast<int64_t>(w.from_s * 1e9), static_cast<int64_t>(w.to_s * 1e9));
        found = true;
      }
    }
    if (!found) throw std::runtime_error("NACK window for '" + w.device + "', which is not on this board");
  }

  avr_global_logger_set(quiet_logger);
  if (elf_read_firmware(opt_.elf.c_str(), &sim_->firmware) != 0) {
    throw std::runtime_error("cannot read the firmware ELF '" + opt_.elf + "' (build it: make -C tools/firmware/gy87_poise)");
  }
  sim_->avr = avr_make_mcu_by_name("atmega328p");
  if (sim_->avr == nullptr) throw std::runtime_error("simavr has no atmega328p");
  avr_init(sim_->avr);
  sim_->avr->frequency = kCpuHz;
  sim_->avr->log = LOG_ERROR;
  avr_load_firmware(sim_->avr, &sim_->firmware);
  static_ram_ = static_cast<int>(sim_->firmware.datasize + sim_->firmware.bsssize);

  uint32_t flags = 0;
  avr_ioctl(sim_->avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
  // No console echo, and no host usleep() while the firmware polls the UART (simavr would sleep
  // in wall-clock time whenever Serial.write() waits for room in its buffer).
  flags &= ~static_cast<uint32_t>(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
  avr_ioctl(sim_->avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
  avr_irq_register_notify(avr_io_getirq(sim_->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                          &Gy87Emulator::uart_hook, this);
  avr_irq_register_notify(avr_io_getirq(sim_->avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT),
                          &Gy87Emulator::twi_hook, this);
  sim_->twi_in = avr_io_getirq(sim_->avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT);
  boot_cycle0_ = sim_->avr->cycle;
  paint_stack();
  if (!opt_.link.empty()) sim_->pty = std::make_unique<imu::PtyLink>(opt_.link);
}

Gy87Emulator::~Gy87Emulator() = default;

int64_t Gy87Emulator::now_ns() const {
  const uint64_t cycles = cycles_done_ + (sim_->avr->cycle - boot_cycle0_);
  return static_cast<int64_t>(cycles * 1000 / (kCpuHz / 1'000'000));  // 16 cycles per us -> ns
}

bool Gy87Emulator::has_reader() const { return sim_->pty && sim_->pty->has_reader(); }

void Gy87Emulator::paint_stack() {
  const int end = sim_->avr->ramend;
  for (int a = kRamStart + static_ram_; a <= end; ++a) sim_->avr->data[a] = kPaint;
}

void Gy87Emulator::measure_stack() {
  const int end = sim_->avr->ramend;
  int a = kRamStart + static_ram_;
  while (a <= end && sim_->avr->data[a] == kPaint) ++a;
  stack_peak_ = std::max(stack_peak_, end + 1 - a);
}

int Gy87Emulator::stack_peak_bytes() const { return stack_peak_; }

void Gy87Emulator::reset_board() {
  measure_stack();
  cycles_done_ += sim_->avr->cycle - boot_cycle0_;
  avr_reset(sim_->avr);
  boot_cycle0_ = sim_->avr->cycle;
  paint_stack();
  std::lock_guard<std::mutex> lock(mu_);
  boot_start_ns_ = now_ns();
  ++boot_;
  in_line_ = false;
}

void Gy87Emulator::run_for(double seconds) {
  const int64_t host0 = monotonic_ns();
  if (host_start_ns_ < 0) {
    host_start_ns_ = host0;
    emu_start_ns_ = now_ns();
    had_reader_ = has_reader();  // a reader there at power-on causes no reset (board plugged in)
  }
  const int64_t end_ns = now_ns() + static_cast<int64_t>(seconds * 1e9);
  while (!stop_ && now_ns() < end_ns) step_chunk();
  measure_stack();
  host_seconds_ += static_cast<double>(monotonic_ns() - host0) * 1e-9;
}

double Gy87Emulator::host_seconds() const { return host_seconds_; }

void Gy87Emulator::step_chunk() {
  // Run up to 1 ms of emulated time, or less when a line ends: its bytes then reach the pty at
  // the host time of its last byte (after the pacing sleep), so the arrival times the driver's
  // clock model sees are the board's, not the chunking's.
  avr_t* avr = sim_->avr;
  const uint64_t target = avr->cycle + kChunkCycles;
  line_ended_ = false;
  while (avr->cycle < target && !line_ended_) {
    const int state = avr_run(avr);
    if (state == cpu_Done || state == cpu_Crashed) {
      throw std::runtime_error("the emulated ATmega328P stopped (simavr state " + std::to_string(state) + ")");
    }
  }
  if (opt_.speed > 0.0) {
    const double rate = opt_.speed * (1.0 + opt_.crystal_ppm * 1e-6);
    const int64_t host_target =
        host_start_ns_ + static_cast<int64_t>(static_cast<double>(now_ns() - emu_start_ns_) / rate);
    timespec ts{};
    ts.tv_sec = host_target / 1'000'000'000;
    ts.tv_nsec = host_target % 1'000'000'000;
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
  }
  if (sim_->pty) {
    const bool reader = sim_->pty->has_reader();
    if (reader && !had_reader_ && opt_.reset_on_open) reset_board();
    had_reader_ = reader;
  }
  std::vector<std::size_t> done;
  std::string bytes;
  {
    std::lock_guard<std::mutex> lock(mu_);
    bytes.swap(pending_);
    done.swap(pending_lines_);
  }
  if (!bytes.empty()) {
    const bool written = sim_->pty && sim_->pty->write(bytes) == imu::PtyLink::WriteStatus::kWritten;
    std::lock_guard<std::mutex> lock(mu_);
    if (!written) {
      for (const std::size_t i : done) lines_[i].lost = true;
      if (in_line_) lines_.back().lost = true;  // its first bytes were in this chunk
    }
    const int64_t host_ns = monotonic_ns();
    for (const std::size_t i : done) {
      lines_[i].delivered = !lines_[i].lost;
      lines_[i].written_host_ns = host_ns;
    }
  }
}

void Gy87Emulator::uart_hook(avr_irq_t* /*irq*/, uint32_t value, void* param) {
  static_cast<Gy87Emulator*>(param)->on_uart_byte(static_cast<uint8_t>(value));
}

void Gy87Emulator::on_uart_byte(uint8_t byte) {
  const char c = static_cast<char>(byte);
  std::lock_guard<std::mutex> lock(mu_);
  uart_.push_back(c);
  pending_.push_back(c);
  if (c == '$') {
    // What the sensors hold now is what this line must carry: the firmware read them all for
    // this sample before it queued the line's first byte.
    LineRecord r;
    r.boot = boot_;
    r.sent_ns = now_ns();
    r.imu = mpu_.last_read();
    // The firmware knows only what it read since it booted (a reset leaves the sensors as they
    // were), and drops a reading when its sensor stops answering.
    const auto stands = [&](const DataRead& d, const I2cDevice& dev) {
      return d.valid && d.t_ns >= boot_start_ns_ && d.t_ns > dev.last_nack_ns();
    };
    if (const auto* mag = dynamic_cast<const AuxMagnetometer*>(mag_.get())) {
      r.mag = mag->last_read();
      r.has_mag = stands(r.mag, *mag) && !r.mag.overflow;
    }
    r.pressure = bmp_.last_pressure_read();
    r.has_pressure = stands(r.pressure, bmp_);
    lines_.push_back(r);
    in_line_ = true;
  } else if (in_line_ && c == '\n') {
    LineRecord& r = lines_.back();
    while (!r.text.empty() && (r.text.back() == '\r' || r.text.back() == '\n')) r.text.pop_back();
    unsigned long seq = 0, t_us = 0;
    r.info = r.text.rfind("$INF,", 0) == 0;
    if (!r.info && std::sscanf(r.text.c_str(), "$%*3[A-Z],%lu,%lu,", &seq, &t_us) == 2) {
      r.seq = static_cast<uint32_t>(seq);
      r.t_us = static_cast<uint32_t>(t_us);
    }
    r.complete = true;
    pending_lines_.push_back(lines_.size() - 1);
    line_ended_ = true;
    in_line_ = false;
  }
  if (in_line_) lines_.back().text.push_back(c);
}

void Gy87Emulator::twi_hook(avr_irq_t* /*irq*/, uint32_t value, void* param) {
  static_cast<Gy87Emulator*>(param)->on_twi(value);
}

void Gy87Emulator::on_twi(uint32_t value) {
  avr_twi_msg_irq_t m{};
  m.u.v = value;
  const uint8_t msg = m.u.twi.msg;
  const uint8_t addr = m.u.twi.addr;
  const int64_t t = now_ns();
  if ((msg & TWI_COND_STOP) != 0) bus_.stop(t);
  if ((msg & TWI_COND_START) != 0) {
    if (bus_.start(addr, t)) avr_raise_irq(sim_->twi_in, avr_twi_irq_msg(TWI_COND_ACK, addr, 1));
  } else if ((msg & TWI_COND_WRITE) != 0) {
    if (bus_.write(m.u.twi.data, t)) avr_raise_irq(sim_->twi_in, avr_twi_irq_msg(TWI_COND_ACK, addr, 1));
  } else if ((msg & TWI_COND_READ) != 0) {
    avr_raise_irq(sim_->twi_in, avr_twi_irq_msg(TWI_COND_READ, addr, bus_.read(t)));
  }
}

std::vector<LineRecord> Gy87Emulator::lines() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<LineRecord> samples;
  samples.reserve(lines_.size());
  for (const LineRecord& r : lines_) {
    // "$IN": a $INF line, also while it is still being sent ("$IMU" differs at its third byte)
    if (!r.info && r.text.rfind("$IN", 0) != 0) samples.push_back(r);
  }
  return samples;
}

std::string Gy87Emulator::uart_text() const {
  std::lock_guard<std::mutex> lock(mu_);
  return uart_;
}

std::vector<Violation> Gy87Emulator::violations() const {
  std::vector<Violation> all;
  for (const I2cDevice* d : bus_.devices()) {
    all.insert(all.end(), d->violations().begin(), d->violations().end());
  }
  return all;
}

uint64_t Gy87Emulator::nacks(const std::string& device) const {
  for (const I2cDevice* d : bus_.devices()) {
    if (d->name() == device) return d->nacks();
  }
  return 0;
}

}  // namespace poise::firmware_emu
