// The GY-87's sensors as I2C register models written from their datasheets' register maps:
// InvenSense MPU-6000/6050 (product specification rev 3.4 and register map rev 4.2), Honeywell
// HMC5883L (3-axis digital compass IC), QST QMC5883L (datasheet 1.0), Bosch BMP180 (BST-BMP180-DS000).
// Each is fed from a known motion (Motion: the project's sensor simulator at 1 kHz, body frame;
// the GY-87's chips share the body axes, the driver's default imu_axes and mag_axes) and records
// what the firmware last read, in SI units before quantisation: what a correct firmware must report.
#pragma once

#include "poise/firmware_emu/i2c.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace poise::sim {
class SensorSimulator;
}

namespace poise::firmware_emu {

/// What the sensors sense at one instant, body frame, SI.
struct MotionSample {
  Eigen::Vector3d accel_mps2{0, 0, 0};  ///< specific force, m/s^2
  Eigen::Vector3d gyro_rps{0, 0, 0};    ///< angular rate, rad/s
  Eigen::Vector3d mag_ut{0, 0, 0};      ///< flux density, uT
  double pressure_pa = 0.0;             ///< static pressure, Pa
  double temperature_c = 0.0;           ///< board temperature, C
};

/// The known motion: the sensor simulator (`scenario`: one of sim::scenario_names(), or "moving":
/// random rotation and translation from power-on; `seed`) sampled at 1 kHz from power-on; at(t)
/// is the sample of the last 1 ms tick at or before t. Temperature: 24 C rising 1 C/min.
class Motion {
 public:
  Motion(const std::string& scenario, uint64_t seed);
  ~Motion();
  Motion(const Motion&) = delete;
  Motion& operator=(const Motion&) = delete;
  MotionSample at(int64_t t_ns);
  static constexpr int64_t kTickNs = 1'000'000;

 private:
  std::unique_ptr<sim::SensorSimulator> sim_;
  std::vector<MotionSample> samples_;
};

/// One read of a sensor's data by the firmware: when, and the SI values it carried.
struct DataRead {
  bool valid = false;       ///< a complete data read happened
  int64_t t_ns = -1;        ///< start of the read transaction
  int64_t sampled_ns = -1;  ///< when the sensor measured what was read
  MotionSample values;
  bool overflow = false;    ///< magnetometer: the part flagged an overflow
};

/// MPU6050 at 0x68: WHO_AM_I 0x75 = 0x68, PWR_MGMT_1 0x6B (reset 0x40: asleep), SMPLRT_DIV 0x19,
/// CONFIG 0x1A, GYRO_CONFIG 0x1B, ACCEL_CONFIG 0x1C, INT_PIN_CFG 0x37, USER_CTRL 0x6A; data
/// 0x3B..0x48 (accel, temperature, gyro; big-endian int16), latched at the 1 kHz sample clock
/// and frozen for a burst read. Rules: no access within 100 ms of power-on (start-up time for
/// register read/write); data read while asleep is zeros; data read within 30 ms of waking
/// (gyro ZRO settling from power-on) is not yet valid.
class Mpu6050 : public RegisterDevice {
 public:
  explicit Mpu6050(Motion& motion, uint8_t address = 0x68);
  /// INT_PIN_CFG.I2C_BYPASS_EN set and USER_CTRL.I2C_MST_EN clear: the auxiliary bus (the
  /// GY-87's magnetometer) is connected to the main bus.
  [[nodiscard]] bool bypass() const;
  [[nodiscard]] const DataRead& last_read() const { return last_; }
  [[nodiscard]] uint8_t reg(uint8_t r) const { return regs_[r]; }
  static constexpr int64_t kStartupNs = 100'000'000;
  static constexpr int64_t kSettleNs = 30'000'000;

 protected:
  void on_write(uint8_t reg, uint8_t value, int64_t t_ns) override;
  uint8_t on_read(uint8_t reg, int64_t t_ns) override;
  void on_read_start(uint8_t reg, int64_t t_ns) override;
  void on_read_end(uint8_t first, int count, int64_t t_ns) override;

 private:
  void reset_registers();
  void check_startup(int64_t t_ns);
  Motion& motion_;
  std::array<uint8_t, 256> regs_{};
  std::array<uint8_t, 14> shadow_{};
  int64_t woke_ns_ = -1;
  DataRead pending_;
  DataRead last_;
};

/// A magnetometer on the MPU6050's auxiliary bus: reachable only while the MPU6050's bypass is
/// on; keeps the measurement last placed in its data registers and the last one read.
class AuxMagnetometer : public RegisterDevice {
 public:
  AuxMagnetometer(std::string name, uint8_t address, Motion& motion, const Mpu6050& host)
      : RegisterDevice(std::move(name), address), motion_(motion), host_(host) {}
  [[nodiscard]] const DataRead& last_read() const { return last_; }

 protected:
  bool reachable() const override { return host_.bypass(); }
  Motion& motion_;
  const Mpu6050& host_;
  DataRead placed_;
  DataRead last_;
  int64_t read_start_ns_ = 0;
};

/// HMC5883L at 0x1E, behind the MPU6050's auxiliary bus: CRA 0x00 (reset 0x10: 15 Hz), CRB 0x01
/// (0x20: 1090 LSB/Ga), MODE 0x02 (0x01: single), data 0x03..0x08 in the order X, Z, Y
/// (big-endian, -4096 on overflow), STATUS 0x09 (RDY, LOCK), ID 0x0A..0x0C "H43". The pointer
/// rolls from 0x08 back to 0x03 and from 0x0C to 0x00. A measurement takes 6 ms; continuous mode
/// measures at the CRA rate. Once some but not all six data registers were read the data is
/// locked (no new measurement placed) until the rest is read or MODE/CRA is written.
/// Rule: data read before the first measurement completed.
class Hmc5883l : public AuxMagnetometer {
 public:
  Hmc5883l(Motion& motion, const Mpu6050& host, uint8_t address = 0x1E);
  static constexpr int64_t kMeasurementNs = 6'000'000;

 protected:
  void on_write(uint8_t reg, uint8_t value, int64_t t_ns) override;
  uint8_t on_read(uint8_t reg, int64_t t_ns) override;
  void on_read_start(uint8_t reg, int64_t t_ns) override;
  void on_read_end(uint8_t first, int count, int64_t t_ns) override;
  uint8_t next_pointer(uint8_t reg) const override;

 private:
  void advance(int64_t t_ns);
  void place(int64_t measured_ns);
  std::array<uint8_t, 13> regs_{};
  int64_t next_measurement_ns_ = -1;  ///< completion time of the next measurement (-1: idle)
  bool continuous_ = false;
  bool have_data_ = false;
  uint8_t read_mask_ = 0;  ///< data registers read since the data was placed/locked
  bool locked_ = false;
};

/// QMC5883L at 0x0D (the GY-87 clones' magnetometer), behind the auxiliary bus too: data
/// 0x00..0x05 X, Y, Z little-endian int16; STATUS 0x06 (DRDY bit 0, OVL bit 1, DOR bit 2; DRDY
/// and DOR cleared by reading a data register); CONTROL1 0x09 (MODE bits 1:0 01 continuous, ODR
/// bits 3:2 10/50/100/200 Hz, RNG bits 5:4 2 G / 8 G, OSR bits 7:6), CONTROL2 0x0A (SOFT_RST bit
/// 7, ROL_PNT bit 6), SET/RESET period 0x0B (the datasheet: write 0x01), chip id 0x0D = 0xFF.
/// Rules: data read before the first measurement; continuous mode without 0x0B = 0x01.
class Qmc5883l : public AuxMagnetometer {
 public:
  Qmc5883l(Motion& motion, const Mpu6050& host, uint8_t address = 0x0D);

 protected:
  void on_write(uint8_t reg, uint8_t value, int64_t t_ns) override;
  uint8_t on_read(uint8_t reg, int64_t t_ns) override;
  void on_read_start(uint8_t reg, int64_t t_ns) override;
  void on_read_end(uint8_t first, int count, int64_t t_ns) override;
  uint8_t next_pointer(uint8_t reg) const override;

 private:
  void reset_registers();
  void advance(int64_t t_ns);
  [[nodiscard]] int64_t period_ns() const;
  std::array<uint8_t, 14> regs_{};
  int64_t next_measurement_ns_ = -1;
  bool have_data_ = false;
};

/// A chip the firmware does not know that answers at `address` (e.g. a QMC5883P at 0x2C):
/// registers read as zeros, writes are accepted.
class UnknownChip : public RegisterDevice {
 public:
  explicit UnknownChip(uint8_t address) : RegisterDevice("unknown", address) {}

 protected:
  void on_write(uint8_t, uint8_t, int64_t) override {}
  uint8_t on_read(uint8_t, int64_t) override { return 0; }
};

/// BMP180 at 0x77: calibration 0xAA..0xBF (the datasheet's example coefficients), chip id 0xD0 =
/// 0x55, soft reset 0xE0 (0xB6), ctrl_meas 0xF4 (0x2E temperature; 0x34 | oss << 6 pressure;
/// SCO bit 5 set while converting), result 0xF6..0xF8 (UT 16 bit; UP = result >> (8 - oss)).
/// Conversion times (max): temperature 4.5 ms, pressure 4.5/7.5/13.5/25.5 ms for oss 0..3. UT is
/// chosen so that the datasheet's compensation gives the true temperature, UP so that it gives
/// the true pressure (with the latest UT). Rules: no access within 10 ms of power-on; result read
/// while converting (the old result is returned) or before any conversion; a conversion started
/// while one runs.
class Bmp180 : public RegisterDevice {
 public:
  explicit Bmp180(Motion& motion, uint8_t address = 0x77);
  /// The last complete read of a pressure result (values.pressure_pa = the true pressure).
  [[nodiscard]] const DataRead& last_pressure_read() const { return last_; }
  /// The datasheet's compensation (section 3.5) with this part's coefficients: 0.1 C and Pa.
  [[nodiscard]] int32_t temperature_decidegc(int32_t ut) const;
  [[nodiscard]] int32_t pressure_pa(int32_t ut, int32_t up, int oss) const;
  static constexpr int64_t kStartupNs = 10'000'000;

 protected:
  void on_write(uint8_t reg, uint8_t value, int64_t t_ns) override;
  uint8_t on_read(uint8_t reg, int64_t t_ns) override;
  void on_read_start(uint8_t reg, int64_t t_ns) override;
  void on_read_end(uint8_t first, int count, int64_t t_ns) override;

 private:
  struct Cal {
    int16_t ac1, ac2, ac3;
    uint16_t ac4, ac5, ac6;
    int16_t b1, b2, mb, mc, md;
  };
  void advance(int64_t t_ns);
  int32_t b5(int32_t ut) const;
  Motion& motion_;
  Cal cal_;
  std::array<uint8_t, 256> regs_{};
  int64_t done_ns_ = -1;       ///< end of the running conversion (-1: none)
  bool pressure_conv_ = false;
  int oss_ = 0;
  int64_t conv_start_ns_ = 0;
  bool have_result_ = false;
  bool result_is_pressure_ = false;
  int32_t last_ut_ = 0;
  DataRead result_;
  DataRead last_;
  int64_t read_start_ns_ = 0;
  uint8_t read_first_ = 0;
};

}  // namespace poise::firmware_emu
