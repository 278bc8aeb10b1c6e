#include "poise/firmware_emu/sensors.h"

#include "poise/sim/sensor_simulator.h"

#include <algorithm>
#include <cmath>

namespace poise::firmware_emu {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kG = 9.80665;  // m/s^2 per g (the MPU6050's LSB/g scale)

int16_t quantise(double value, double lsb_per_unit, int lo = -32768, int hi = 32767) {
  const double counts = std::round(value * lsb_per_unit);
  return static_cast<int16_t>(std::clamp(counts, static_cast<double>(lo), static_cast<double>(hi)));
}

void put_be(uint8_t* p, int16_t v) {
  p[0] = static_cast<uint8_t>((static_cast<uint16_t>(v) >> 8) & 0xFF);
  p[1] = static_cast<uint8_t>(static_cast<uint16_t>(v) & 0xFF);
}

void put_le(uint8_t* p, int16_t v) {
  p[0] = static_cast<uint8_t>(static_cast<uint16_t>(v) & 0xFF);
  p[1] = static_cast<uint8_t>((static_cast<uint16_t>(v) >> 8) & 0xFF);
}

}  // namespace

// ------------------------------------------------------------------------------------ Motion
Motion::Motion(const std::string& scenario, uint64_t seed) {
  sim::SimConfig cfg;
  if (scenario == "moving") {
    // Moving from power-on (the simulator's scenarios all start at rest): random rotation up
    // to ~3 rad/s per axis and translation up to ~5 m/s^2, inside the GY-87's ranges.
    cfg.rate_hz = 1000.0;
    cfg.seed = seed;
    sim::MotionSegment m;
    m.name = "moving";
    m.duration_s = 60.0;
    m.rotation_amplitude_rps = 3.0;
    m.rotation_freq_hz = 0.8;
    m.level_gain_per_s = 0.5;
    m.accel_amplitude_mps2 = 5.0;
    m.accel_freq_hz = 1.0;
    cfg.segments = {m};
  } else {
    cfg = sim::make_scenario(scenario, 1000.0, seed);
  }
  cfg.duration_s = 0.0;  // endless: the board may run as long as a test wants
  sim_ = std::make_unique<sim::SensorSimulator>(cfg);
}

Motion::~Motion() = default;

MotionSample Motion::at(int64_t t_ns) {
  const auto k = static_cast<std::size_t>(std::max<int64_t>(t_ns, 0) / kTickNs);
  while (samples_.size() <= k) {
    const sim::SimSample s = sim_->next();
    MotionSample m;
    m.accel_mps2 = s.imu.accel_mps2;
    m.gyro_rps = s.imu.gyro_rps;
    m.mag_ut = s.imu.mag_ut;
    m.pressure_pa = s.imu.pressure_pa;
    m.temperature_c = 24.0 + static_cast<double>(samples_.size()) * 1e-3 / 60.0;
    samples_.push_back(m);
  }
  return samples_[k];
}

// ----------------------------------------------------------------------------------- MPU6050
Mpu6050::Mpu6050(Motion& motion, uint8_t address) : RegisterDevice("MPU6050", address), motion_(motion) {
  reset_registers();
}

void Mpu6050::reset_registers() {
  regs_.fill(0);
  regs_[0x6B] = 0x40;  // PWR_MGMT_1: SLEEP
  regs_[0x75] = 0x68;  // WHO_AM_I
  shadow_.fill(0);
  woke_ns_ = -1;
}

bool Mpu6050::bypass() const { return (regs_[0x37] & 0x02) != 0 && (regs_[0x6A] & 0x20) == 0; }

void Mpu6050::check_startup(int64_t t_ns) {
  if (t_ns < kStartupNs) violate(t_ns, "register access within 100 ms of power-on");
}

void Mpu6050::on_write(uint8_t reg, uint8_t value, int64_t t_ns) {
  check_startup(t_ns);
  if (reg == 0x6B) {
    if ((value & 0x80) != 0) {  // DEVICE_RESET
      reset_registers();
      return;
    }
    const bool was_asleep = (regs_[0x6B] & 0x40) != 0;
    regs_[0x6B] = value;
    if ((value & 0x40) != 0) {
      woke_ns_ = -1;
    } else if (was_asleep) {
      woke_ns_ = t_ns;
    }
    return;
  }
  if (reg == 0x75 || (reg >= 0x3B && reg <= 0x48)) return;  // read-only
  regs_[reg] = value;
}

void Mpu6050::on_read_start(uint8_t reg, int64_t t_ns) {
  check_startup(t_ns);
  if (reg < 0x3B || reg > 0x48) return;
  // The data registers are latched at the sample clock (1 kHz with the DLPF on) and hold still
  // during a burst read.
  pending_ = DataRead{};
  pending_.t_ns = t_ns;
  if (woke_ns_ < 0) {
    violate(t_ns, "data read while asleep (PWR_MGMT_1.SLEEP): registers hold no measurement");
    return;  // the shadow keeps what it had (zeros after power-on)
  }
  if (t_ns - woke_ns_ < kSettleNs) violate(t_ns, "data read within 30 ms of waking (gyro start-up)");
  pending_.sampled_ns = t_ns / Motion::kTickNs * Motion::kTickNs;
  pending_.values = motion_.at(t_ns);
  const int afs = (regs_[0x1C] >> 3) & 3;
  const int gfs = (regs_[0x1B] >> 3) & 3;
  const double accel_lsb = 16384.0 / (1 << afs) / kG;         // counts per m/s^2
  const double gyro_lsb = 131.0 / (1 << gfs) * 180.0 / kPi;   // counts per rad/s
  const MotionSample& v = pending_.values;
  for (int i = 0; i < 3; ++i) {
    put_be(&shadow_[static_cast<std::size_t>(2 * i)], quantise(v.accel_mps2[i], accel_lsb));
    put_be(&shadow_[static_cast<std::size_t>(8 + 2 * i)], quantise(v.gyro_rps[i], gyro_lsb));
  }
  put_be(&shadow_[6], quantise(v.temperature_c - 36.53, 340.0));
  pending_.valid = true;
}

uint8_t Mpu6050::on_read(uint8_t reg, int64_t t_ns) {
  check_startup(t_ns);
  if (reg >= 0x3B && reg <= 0x48) return shadow_[static_cast<std::size_t>(reg - 0x3B)];
  return regs_[reg];
}

void Mpu6050::on_read_end(uint8_t first, int count, int64_t /*t_ns*/) {
  if (first == 0x3B && count >= 14 && pending_.valid) last_ = pending_;
}

// ---------------------------------------------------------------------------------- HMC5883L
Hmc5883l::Hmc5883l(Motion& motion, const Mpu6050& host, uint8_t address)
    : AuxMagnetometer("HMC5883L", address, motion, host) {
  regs_[0x00] = 0x10;  // CRA: 1 sample, 15 Hz
  regs_[0x01] = 0x20;  // CRB: gain 1090 LSB/Ga
  regs_[0x02] = 0x01;  // MODE: single measurement (idle after power-on)
  regs_[0x0A] = 'H';
  regs_[0x0B] = '4';
  regs_[0x0C] = '3';
}

uint8_t Hmc5883l::next_pointer(uint8_t reg) const {
  if (reg == 0x08) return 0x03;
  if (reg >= 0x0C) return 0x00;
  return static_cast<uint8_t>(reg + 1);
}

void Hmc5883l::advance(int64_t t_ns) {
  static constexpr double kRateHz[8] = {0.75, 1.5, 3.0, 7.5, 15.0, 30.0, 75.0, 75.0};
  while (next_measurement_ns_ >= 0 && next_measurement_ns_ <= t_ns) {
    place(next_measurement_ns_ - kMeasurementNs);
    if (continuous_) {
      next_measurement_ns_ += static_cast<int64_t>(1e9 / kRateHz[(regs_[0x00] >> 2) & 7]);
    } else {
      next_measurement_ns_ = -1;
      regs_[0x02] = static_cast<uint8_t>((regs_[0x02] & ~3) | 3);  // back to idle
    }
  }
}

void Hmc5883l::place(int64_t measured_ns) {
  if (locked_) return;  // some but not all data registers were read: the new data is lost
  static constexpr double kGainLsbPerGauss[8] = {1370, 1090, 820, 660, 440, 390, 330, 230};
  const MotionSample s = motion_.at(measured_ns);
  const double lsb_per_ut = kGainLsbPerGauss[regs_[0x01] >> 5] / 100.0;
  bool overflow = false;
  int16_t c[3];
  for (int i = 0; i < 3; ++i) {
    const double counts = std::round(s.mag_ut[i] * lsb_per_ut);
    if (counts < -2048 || counts > 2047) {
      c[i] = -4096;
      overflow = true;
    } else {
      c[i] = static_cast<int16_t>(counts);
    }
  }
  put_be(&regs_[0x03], c[0]);  // X
  put_be(&regs_[0x05], c[2]);  // Z
  put_be(&regs_[0x07], c[1]);  // Y
  regs_[0x09] |= 0x01;         // RDY
  placed_ = DataRead{true, -1, measured_ns, s, overflow};
  have_data_ = true;
  read_mask_ = 0;
}

void Hmc5883l::on_write(uint8_t reg, uint8_t value, int64_t t_ns) {
  advance(t_ns);
  if (reg > 0x02) return;  // read-only
  regs_[reg] = value;
  if (reg == 0x01) return;
  locked_ = false;  // writing MODE or CRA releases the lock
  read_mask_ = 0;
  if (reg == 0x02) {
    const int mode = value & 3;
    continuous_ = mode == 0;
    next_measurement_ns_ = mode <= 1 ? t_ns + kMeasurementNs : -1;
  }
}

void Hmc5883l::on_read_start(uint8_t reg, int64_t t_ns) {
  advance(t_ns);
  read_start_ns_ = t_ns;
  if (reg >= 0x03 && reg <= 0x08 && !have_data_) {
    violate(t_ns, "data read before the first measurement completed (6 ms)");
  }
  if (reg == 0x02) {
    locked_ = true;  // reading MODE locks the data registers (datasheet, status register)
  }
}

uint8_t Hmc5883l::on_read(uint8_t reg, int64_t /*t_ns*/) {
  if (reg >= 0x03 && reg <= 0x08) {
    read_mask_ = static_cast<uint8_t>(read_mask_ | (1u << (reg - 0x03)));
    locked_ = read_mask_ != 0x3F;
    if (!locked_) {
      if (placed_.valid) {
        last_ = placed_;
        last_.t_ns = read_start_ns_;
      }
      read_mask_ = 0;
    }
  }
  if (reg == 0x09) return static_cast<uint8_t>((regs_[0x09] & 0x01) | (locked_ ? 0x02 : 0x00));
  return reg <= 0x0C ? regs_[reg] : 0;
}

void Hmc5883l::on_read_end(uint8_t, int, int64_t) {}

// ---------------------------------------------------------------------------------- QMC5883L
Qmc5883l::Qmc5883l(Motion& motion, const Mpu6050& host, uint8_t address)
    : AuxMagnetometer("QMC5883L", address, motion, host) {
  reset_registers();
}

void Qmc5883l::reset_registers() {
  regs_.fill(0);
  regs_[0x0C] = 0x01;
  regs_[0x0D] = 0xFF;  // chip id
  next_measurement_ns_ = -1;
  have_data_ = false;
}

int64_t Qmc5883l::period_ns() const {
  static constexpr int64_t kRateHz[4] = {10, 50, 100, 200};
  return 1'000'000'000 / kRateHz[(regs_[0x09] >> 2) & 3];
}

uint8_t Qmc5883l::next_pointer(uint8_t reg) const {
  if ((regs_[0x0A] & 0x40) != 0 && reg == 0x06) return 0x00;  // ROL_PNT
  return static_cast<uint8_t>(reg + 1);
}

void Qmc5883l::advance(int64_t t_ns) {
  while (next_measurement_ns_ >= 0 && next_measurement_ns_ <= t_ns) {
    const int64_t measured_ns = next_measurement_ns_ - period_ns();
    const MotionSample s = motion_.at(std::max<int64_t>(measured_ns, 0));
    const double lsb_per_ut = ((regs_[0x09] >> 4) & 3) == 0 ? 120.0 : 30.0;  // 12000 / 3000 LSB/G
    bool overflow = false;
    for (int i = 0; i < 3; ++i) {
      const double counts = std::round(s.mag_ut[i] * lsb_per_ut);
      if (std::abs(counts) > 32767) overflow = true;
      put_le(&regs_[static_cast<std::size_t>(2 * i)], quantise(s.mag_ut[i], lsb_per_ut));
    }
    uint8_t status = regs_[0x06];
    if ((status & 0x01) != 0) status |= 0x04;  // DOR: the previous data was never read
    status = static_cast<uint8_t>((status & ~0x02) | 0x01 | (overflow ? 0x02 : 0x00));
    regs_[0x06] = status;
    placed_ = DataRead{true, -1, measured_ns, s, overflow};
    have_data_ = true;
    next_measurement_ns_ += period_ns();
  }
}

void Qmc5883l::on_write(uint8_t reg, uint8_t value, int64_t t_ns) {
  advance(t_ns);
  if (reg == 0x0A && (value & 0x80) != 0) {  // SOFT_RST
    reset_registers();
    return;
  }
  if (reg < 0x09 || reg > 0x0B) return;  // read-only
  regs_[reg] = value;
  if (reg == 0x09) {
    if ((value & 3) == 1) {
      if (regs_[0x0B] != 0x01) violate(t_ns, "continuous mode without SET/RESET period 0x0B = 0x01");
      if (next_measurement_ns_ < 0) next_measurement_ns_ = t_ns + period_ns();
    } else {
      next_measurement_ns_ = -1;
    }
  }
}

void Qmc5883l::on_read_start(uint8_t reg, int64_t t_ns) {
  advance(t_ns);
  read_start_ns_ = t_ns;
  if (reg <= 0x05 && !have_data_) violate(t_ns, "data read before the first measurement completed");
}

uint8_t Qmc5883l::on_read(uint8_t reg, int64_t /*t_ns*/) {
  const uint8_t v = reg < regs_.size() ? regs_[reg] : 0;
  if (reg <= 0x05) regs_[0x06] = static_cast<uint8_t>(regs_[0x06] & ~0x05);  // DRDY, DOR cleared
  return v;
}

void Qmc5883l::on_read_end(uint8_t first, int count, int64_t /*t_ns*/) {
  if (first == 0x00 && count >= 6 && placed_.valid) {
    last_ = placed_;
    last_.t_ns = read_start_ns_;
  }
}

// ------------------------------------------------------------------------------------ BMP180
Bmp180::Bmp180(Motion& motion, uint8_t address)
    : RegisterDevice("BMP180", address),
      motion_(motion),
      cal_{408, -72, -14383, 32741, 32757, 23153, 6190, 4, -32768, -8711, 2868} {  // datasheet 3.5
  const int16_t words[11] = {cal_.ac1, cal_.ac2, cal_.ac3, static_cast<int16_t>(cal_.ac4),
                             static_cast<int16_t>(cal_.ac5), static_cast<int16_t>(cal_.ac6), cal_.b1,
                             cal_.b2, cal_.mb, cal_.mc, cal_.md};
  for (int i = 0; i < 11; ++i) put_be(&regs_[static_cast<std::size_t>(0xAA + 2 * i)], words[i]);
  regs_[0xD0] = 0x55;
  regs_[0xF6] = 0x80;  // out_msb reset value
}

int32_t Bmp180::b5(int32_t ut) const {
  const int32_t x1 = ((ut - static_cast<int32_t>(cal_.ac6)) * static_cast<int32_t>(cal_.ac5)) >> 15;
  const int32_t den = x1 + cal_.md;
  if (den == 0) return x1 > 0 ? INT32_MAX / 2 : INT32_MIN / 2;
  const int32_t x2 = (static_cast<int32_t>(cal_.mc) * 2048) / den;
  return x1 + x2;
}

int32_t Bmp180::temperature_decidegc(int32_t ut) const { return (b5(ut) + 8) >> 4; }

int32_t Bmp180::pressure_pa(int32_t ut, int32_t up, int oss) const {
  // Bosch BMP180 datasheet, section 3.5 ("calculate true pressure"), in 32-bit arithmetic.
  const int32_t b6 = b5(ut) - 4000;
  int32_t x1 = (cal_.b2 * ((b6 * b6) >> 12)) >> 11;
  int32_t x2 = (cal_.ac2 * b6) >> 11;
  int32_t x3 = x1 + x2;
  const int32_t b3 = (((static_cast<int32_t>(cal_.ac1) * 4 + x3) << oss) + 2) / 4;
  x1 = (cal_.ac3 * b6) >> 13;
  x2 = (cal_.b1 * ((b6 * b6) >> 12)) >> 16;
  x3 = ((x1 + x2) + 2) >> 2;
  const uint32_t b4 = (static_cast<uint32_t>(cal_.ac4) * static_cast<uint32_t>(x3 + 32768)) >> 15;
  if (b4 == 0) return 0;
  const uint32_t b7 = (static_cast<uint32_t>(up) - static_cast<uint32_t>(b3)) * (50000u >> oss);
  int32_t p = b7 < 0x80000000u ? static_cast<int32_t>((b7 * 2) / b4) : static_cast<int32_t>((b7 / b4) * 2);
  x1 = (p >> 8) * (p >> 8);
  x1 = (x1 * 3038) >> 16;
  x2 = (-7357 * p) >> 16;
  return p + ((x1 + x2 + 3791) >> 4);
}

void Bmp180::advance(int64_t t_ns) {
  if (done_ns_ < 0 || done_ns_ > t_ns) return;
  const MotionSample s = motion_.at(conv_start_ns_);
  if (!pressure_conv_) {
    // UT whose compensated temperature is nearest the true one (monotonic in UT above the pole
    // of x2, which sits near UT = ac6 - md).
    const double target = s.temperature_c * 10.0;
    int32_t lo = cal_.ac6 - cal_.md + 512, hi = 65535;
    while (lo < hi) {
      const int32_t mid = lo + (hi - lo) / 2;
      if (temperature_decidegc(mid) < target) lo = mid + 1; else hi = mid;
    }
    last_ut_ = lo;
    regs_[0xF6] = static_cast<uint8_t>(lo >> 8);
    regs_[0xF7] = static_cast<uint8_t>(lo & 0xFF);
    result_is_pressure_ = false;
  } else {
    // UP whose compensated pressure (with the latest UT) is nearest the true pressure.
    int32_t lo = 0, hi = (1 << (16 + oss_)) - 1;
    while (lo < hi) {
      const int32_t mid = lo + (hi - lo) / 2;
      if (pressure_pa(last_ut_, mid, oss_) < s.pressure_pa) lo = mid + 1; else hi = mid;
    }
    if (lo > 0 && std::abs(pressure_pa(last_ut_, lo - 1, oss_) - s.pressure_pa) <
                      std::abs(pressure_pa(last_ut_, lo, oss_) - s.pressure_pa)) {
      --lo;
    }
    const uint32_t raw = static_cast<uint32_t>(lo) << (8 - oss_);
    regs_[0xF6] = static_cast<uint8_t>((raw >> 16) & 0xFF);
    regs_[0xF7] = static_cast<uint8_t>((raw >> 8) & 0xFF);
    regs_[0xF8] = static_cast<uint8_t>(raw & 0xFF);
    result_ = DataRead{true, -1, conv_start_ns_, s, false};
    result_is_pressure_ = true;
  }
  have_result_ = true;
  regs_[0xF4] = static_cast<uint8_t>(regs_[0xF4] & ~0x20);  // SCO: done
  done_ns_ = -1;
}

void Bmp180::on_write(uint8_t reg, uint8_t value, int64_t t_ns) {
  if (t_ns < kStartupNs) violate(t_ns, "register access within 10 ms of power-on");
  advance(t_ns);
  if (reg == 0xE0 && value == 0xB6) {  // soft reset
    done_ns_ = -1;
    have_result_ = false;
    regs_[0xF4] = 0;
    return;
  }
  if (reg != 0xF4) return;  // the rest is read-only
  static constexpr int64_t kPressureNs[4] = {4'500'000, 7'500'000, 13'500'000, 25'500'000};
  if (done_ns_ >= 0) violate(t_ns, "conversion started while one runs");
  regs_[0xF4] = value;
  const int kind = value & 0x1F;
  if ((value & 0x20) == 0 || (kind != 0x0E && kind != 0x14)) return;  // no conversion started
  pressure_conv_ = kind == 0x14;
  oss_ = value >> 6;
  conv_start_ns_ = t_ns;
  done_ns_ = t_ns + (pressure_conv_ ? kPressureNs[oss_] : 4'500'000);
}

void Bmp180::on_read_start(uint8_t reg, int64_t t_ns) {
  if (t_ns < kStartupNs) violate(t_ns, "register access within 10 ms of power-on");
  advance(t_ns);
  read_start_ns_ = t_ns;
  read_first_ = reg;
  if (reg >= 0xF6 && reg <= 0xF8) {
    if (done_ns_ >= 0) {
      violate(t_ns, "result read while converting (SCO = 1): the old result is returned");
    } else if (!have_result_) {
      violate(t_ns, "result read before any conversion");
    }
  }
}

uint8_t Bmp180::on_read(uint8_t reg, int64_t /*t_ns*/) { return regs_[reg]; }

void Bmp180::on_read_end(uint8_t first, int count, int64_t /*t_ns*/) {
  if (first == 0xF6 && count >= 3 && result_is_pressure_ && done_ns_ < 0 && have_result_) {
    last_ = result_;
    last_.t_ns = read_start_ns_;
  }
}

}  // namespace poise::firmware_emu
