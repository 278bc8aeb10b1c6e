// The sensor models of the emulated GY-87 (tests/firmware/src/sensors.cpp) driven over the I2C bus
// directly: they answer as the datasheets say and reject what the parts reject, so that a
// firmware mistake in the emulated-board tests is a violation and a wrong value, not a plausible
// number. Oracles: the datasheets' register maps, reset values and worked example.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "poise/firmware_emu/sensors.h"

namespace poise::firmware_emu {
namespace {

constexpr int64_t kMs = 1'000'000;
constexpr double kG = 9.80665;
constexpr double kPi = 3.14159265358979323846;

bool write_reg(I2cBus& bus, uint8_t addr, uint8_t reg, uint8_t value, int64_t t_ns) {
  const bool ok = bus.start(static_cast<uint8_t>(addr << 1), t_ns) && bus.write(reg, t_ns) &&
                  bus.write(value, t_ns);
  bus.stop(t_ns);
  return ok;
}

/// Pointer write, repeated start, n bytes read (what Arduino's Wire does); empty on a NACK.
std::vector<uint8_t> read_regs(I2cBus& bus, uint8_t addr, uint8_t reg, int n, int64_t t_ns) {
  std::vector<uint8_t> out;
  if (!bus.start(static_cast<uint8_t>(addr << 1), t_ns) || !bus.write(reg, t_ns)) {
    bus.stop(t_ns);
    return out;
  }
  if (!bus.start(static_cast<uint8_t>(addr << 1 | 1), t_ns)) {
    bus.stop(t_ns);
    return out;
  }
  for (int i = 0; i < n; ++i) out.push_back(bus.read(t_ns));
  bus.stop(t_ns);
  return out;
}

int16_t be(const std::vector<uint8_t>& b, int i) {
  return static_cast<int16_t>(static_cast<uint16_t>(b[static_cast<std::size_t>(i)] << 8) |
                              b[static_cast<std::size_t>(i + 1)]);
}

bool has_violation(const I2cDevice& d, const std::string& part) {
  for (const Violation& v : d.violations()) {
    if (v.rule.find(part) != std::string::npos) return true;
  }
  return false;
}

struct Board {
  Motion motion{"moving", 3};
  Mpu6050 mpu{motion};
  Hmc5883l hmc{motion, mpu};
  Qmc5883l qmc{motion, mpu};
  Bmp180 bmp{motion};
  I2cBus bus;
  Board() {
    for (I2cDevice* d : std::vector<I2cDevice*>{&mpu, &hmc, &qmc, &bmp}) bus.attach(d);
  }
  void wake_mpu_with_bypass(int64_t t_ns) {
    write_reg(bus, 0x68, 0x6B, 0x01, t_ns);
    write_reg(bus, 0x68, 0x37, 0x02, t_ns);
  }
};

TEST(Mpu6050Model, GivenPowerOnThenWhoAmIIs0x68AndDataReadBeforeWakingIsZerosAndAViolation) {
  Board b;
  EXPECT_EQ(read_regs(b.bus, 0x68, 0x75, 1, 150 * kMs), std::vector<uint8_t>{0x68});
  EXPECT_EQ(read_regs(b.bus, 0x68, 0x6B, 1, 150 * kMs), std::vector<uint8_t>{0x40});  // asleep
  const auto d = read_regs(b.bus, 0x68, 0x3B, 14, 150 * kMs);
  ASSERT_EQ(d.size(), 14u);
  for (const uint8_t x : d) EXPECT_EQ(x, 0);
  EXPECT_TRUE(has_violation(b.mpu, "asleep"));
  EXPECT_FALSE(b.mpu.last_read().valid);
}

TEST(Mpu6050Model, GivenAccessWithin100msOfPowerOnThenAViolation) {
  Board b;
  read_regs(b.bus, 0x68, 0x75, 1, 50 * kMs);
  EXPECT_TRUE(has_violation(b.mpu, "100 ms"));
}

TEST(Mpu6050Model, GivenFourGAndFiveHundredDpsWhenReadAfterSettlingThenTheBurstHoldsTheMotionInCounts) {
  Board b;
  b.wake_mpu_with_bypass(100 * kMs);
  write_reg(b.bus, 0x68, 0x1B, 1 << 3, 100 * kMs);  // +-500 dps
  write_reg(b.bus, 0x68, 0x1C, 1 << 3, 100 * kMs);  // +-4 g
  const int64_t t = 200 * kMs + 400'000;
  const auto d = read_regs(b.bus, 0x68, 0x3B, 14, t);
  ASSERT_EQ(d.size(), 14u);
  EXPECT_TRUE(b.mpu.violations().empty());
  const MotionSample m = b.motion.at(t);
  // Oracle: register map 4.17/4.19/4.18: ACCEL = a / g * 8192, GYRO = w (deg/s) * 65.5,
  // TEMP = (T - 36.53) * 340, each rounded to the nearest count.
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(be(d, 2 * i), std::lround(m.accel_mps2[i] / kG * 8192.0)) << i;
    EXPECT_EQ(be(d, 8 + 2 * i), std::lround(m.gyro_rps[i] * 180.0 / kPi * 65.5)) << i;
  }
  EXPECT_EQ(be(d, 6), std::lround((m.temperature_c - 36.53) * 340.0));
  ASSERT_TRUE(b.mpu.last_read().valid);
  EXPECT_EQ(b.mpu.last_read().sampled_ns, 200 * kMs);  // the 1 kHz tick before the read
}

TEST(Mpu6050Model, GivenADataReadWithin30msOfWakingThenAViolation) {
  Board b;
  b.wake_mpu_with_bypass(100 * kMs);
  read_regs(b.bus, 0x68, 0x3B, 14, 110 * kMs);
  EXPECT_TRUE(has_violation(b.mpu, "30 ms"));
}

TEST(Hmc5883lModel, GivenTheMpuBypassClosedThenTheMagnetometerDoesNotAcknowledge) {
  Board b;
  write_reg(b.bus, 0x68, 0x6B, 0x01, 100 * kMs);
  EXPECT_TRUE(read_regs(b.bus, 0x1E, 0x0A, 3, 101 * kMs).empty());
  EXPECT_EQ(b.hmc.nacks(), 1u);
  write_reg(b.bus, 0x68, 0x37, 0x02, 102 * kMs);
  EXPECT_EQ(read_regs(b.bus, 0x1E, 0x0A, 3, 103 * kMs), (std::vector<uint8_t>{'H', '4', '3'}));
  write_reg(b.bus, 0x68, 0x6A, 0x20, 104 * kMs);  // I2C master on: the aux bus is the MPU's again
  EXPECT_TRUE(read_regs(b.bus, 0x1E, 0x0A, 3, 105 * kMs).empty());
}

TEST(Hmc5883lModel, GivenContinuousModeThenDataBeforeTheFirstMeasurementIsAViolationAndLaterDataIsXZY) {
  Board b;
  b.wake_mpu_with_bypass(100 * kMs);
  write_reg(b.bus, 0x1E, 0x00, 0x18, 101 * kMs);  // 75 Hz
  write_reg(b.bus, 0x1E, 0x01, 0x20, 101 * kMs);  // 1090 LSB/Ga
  write_reg(b.bus, 0x1E, 0x02, 0x00, 101 * kMs);  // continuous
  read_regs(b.bus, 0x1E, 0x03, 6, 104 * kMs);
  EXPECT_TRUE(has_violation(b.hmc, "first measurement"));
  const auto d = read_regs(b.bus, 0x1E, 0x03, 6, 120 * kMs);
  ASSERT_EQ(d.size(), 6u);
  // Measurements complete at 107 ms (measured from 101 ms) and every 13.3 ms (75 Hz) after: at
  // 120 ms the second (120.3 ms) is not done, so the data is the one measured from 101 ms.
  const MotionSample m = b.motion.at(101 * kMs);
  EXPECT_EQ(be(d, 0), std::lround(m.mag_ut.x() * 10.9));  // X
  EXPECT_EQ(be(d, 2), std::lround(m.mag_ut.z() * 10.9));  // Z
  EXPECT_EQ(be(d, 4), std::lround(m.mag_ut.y() * 10.9));  // Y
  // The pointer rolls from 0x08 back to 0x03: eight bytes from 0x03 end with X again.
  const auto e = read_regs(b.bus, 0x1E, 0x03, 8, 121 * kMs);
  EXPECT_EQ(be(e, 6), be(e, 0));
}

TEST(Hmc5883lModel, GivenAPartialDataReadThenNewMeasurementsAreNotPlacedUntilTheRestIsRead) {
  Board b;
  b.wake_mpu_with_bypass(100 * kMs);
  write_reg(b.bus, 0x1E, 0x00, 0x18, 101 * kMs);
  write_reg(b.bus, 0x1E, 0x02, 0x00, 101 * kMs);
  const auto first = read_regs(b.bus, 0x1E, 0x03, 2, 110 * kMs);  // X only: locked
  const auto later = read_regs(b.bus, 0x1E, 0x03, 6, 500 * kMs);   // still the 101 ms data
  EXPECT_EQ(be(later, 0), be(first, 0));
  EXPECT_EQ(b.hmc.last_read().sampled_ns, 101 * kMs);
  const auto fresh = read_regs(b.bus, 0x1E, 0x03, 6, 600 * kMs);  // unlocked: newer data
  EXPECT_GT(b.hmc.last_read().sampled_ns, 500 * kMs);
  (void)fresh;
}

TEST(Qmc5883lModel, GivenContinuousModeWithoutTheSetResetPeriodThenAViolation) {
  Board b;
  b.wake_mpu_with_bypass(100 * kMs);
  EXPECT_EQ(read_regs(b.bus, 0x0D, 0x0D, 1, 101 * kMs), std::vector<uint8_t>{0xFF});  // chip id
  write_reg(b.bus, 0x0D, 0x09, 0x09, 101 * kMs);
  EXPECT_TRUE(has_violation(b.qmc, "0x0B"));
}

TEST(Qmc5883lModel, GivenContinuousModeThenDrdyDorAndLittleEndianXYZAsTheDatasheetSays) {
  Board b;
  b.wake_mpu_with_bypass(100 * kMs);
  write_reg(b.bus, 0x0D, 0x0B, 0x01, 101 * kMs);
  write_reg(b.bus, 0x0D, 0x09, 0x09, 101 * kMs);  // 100 Hz, 2 G, continuous
  read_regs(b.bus, 0x0D, 0x00, 6, 105 * kMs);
  EXPECT_TRUE(has_violation(b.qmc, "first measurement"));
  EXPECT_EQ(read_regs(b.bus, 0x0D, 0x06, 1, 112 * kMs)[0] & 0x05, 0x01);  // DRDY, no DOR
  EXPECT_EQ(read_regs(b.bus, 0x0D, 0x06, 1, 122 * kMs)[0] & 0x05, 0x05);  // skipped one: DOR
  const auto d = read_regs(b.bus, 0x0D, 0x00, 6, 122 * kMs);
  EXPECT_EQ(read_regs(b.bus, 0x0D, 0x06, 1, 122 * kMs)[0] & 0x05, 0x00);  // cleared by the read
  const MotionSample m = b.motion.at(111 * kMs);  // measured over the 10 ms before 121 ms
  for (int i = 0; i < 3; ++i) {
    const auto v = static_cast<int16_t>(d[static_cast<std::size_t>(2 * i)] |
                                        d[static_cast<std::size_t>(2 * i + 1)] << 8);
    EXPECT_EQ(v, std::lround(m.mag_ut[i] * 120.0)) << i;  // 12000 LSB/G = 120 LSB/uT
  }
}

TEST(Bmp180Model, GivenTheDatasheetExampleThenTheCompensationGives15CAnd69964Pa) {
  Board b;
  EXPECT_EQ(b.bmp.temperature_decidegc(27898), 150);   // BMP180 datasheet 3.5
  EXPECT_EQ(b.bmp.pressure_pa(27898, 23843, 0), 69964);
  EXPECT_EQ(read_regs(b.bus, 0x77, 0xD0, 1, 20 * kMs), std::vector<uint8_t>{0x55});
  const auto cal = read_regs(b.bus, 0x77, 0xAA, 22, 20 * kMs);
  EXPECT_EQ(be(cal, 0), 408);      // AC1
  EXPECT_EQ(be(cal, 18), -8711);   // MC
}

TEST(Bmp180Model, GivenAResultReadBeforeTheConversionTimeThenAViolation) {
  Board b;
  write_reg(b.bus, 0x77, 0xF4, 0x2E, 20 * kMs);
  EXPECT_EQ(read_regs(b.bus, 0x77, 0xF4, 1, 21 * kMs)[0] & 0x20, 0x20);  // SCO while converting
  read_regs(b.bus, 0x77, 0xF6, 2, 23 * kMs);                              // 3 ms < 4.5 ms
  EXPECT_TRUE(has_violation(b.bmp, "while converting"));
  write_reg(b.bus, 0x77, 0xF4, 0x74, 23 * kMs);
  EXPECT_TRUE(has_violation(b.bmp, "started while one runs"));
}

TEST(Bmp180Model, GivenATrueTemperatureAndPressureThenTheRawValuesCompensateToThemWithinOneStep) {
  Board b;
  write_reg(b.bus, 0x77, 0xF4, 0x2E, 20 * kMs);
  const auto ut_b = read_regs(b.bus, 0x77, 0xF6, 2, 25 * kMs);
  const int32_t ut = static_cast<uint16_t>(be(ut_b, 0));
  write_reg(b.bus, 0x77, 0xF4, 0x74, 25 * kMs);  // oss 1
  const auto up_b = read_regs(b.bus, 0x77, 0xF6, 3, 33 * kMs);
  EXPECT_TRUE(b.bmp.violations().empty());
  const int32_t up = ((up_b[0] << 16) | (up_b[1] << 8) | up_b[2]) >> 7;
  const MotionSample t_truth = b.motion.at(20 * kMs);
  const MotionSample p_truth = b.motion.at(25 * kMs);
  EXPECT_NEAR(b.bmp.temperature_decidegc(ut) / 10.0, t_truth.temperature_c, 0.1);
  const int32_t step = b.bmp.pressure_pa(ut, up + 1, 1) - b.bmp.pressure_pa(ut, up, 1);
  // At oss 1 one UP count is about 1.5 Pa of compensated pressure, in whole Pa: 1 or 2.
  constexpr int32_t kMaxStepPa = 2;
  EXPECT_LE(step, kMaxStepPa);
  EXPECT_LE(std::abs(b.bmp.pressure_pa(ut, up, 1) - p_truth.pressure_pa), 0.5 * kMaxStepPa);
  ASSERT_TRUE(b.bmp.last_pressure_read().valid);
  EXPECT_DOUBLE_EQ(b.bmp.last_pressure_read().values.pressure_pa, p_truth.pressure_pa);
}

TEST(I2cBusModel, GivenANackWindowThenTheDeviceIgnoresItsAddressOnlyInsideIt) {
  Board b;
  b.mpu.add_nack_window(200 * kMs, 300 * kMs);
  EXPECT_EQ(read_regs(b.bus, 0x68, 0x75, 1, 199 * kMs).size(), 1u);
  EXPECT_TRUE(read_regs(b.bus, 0x68, 0x75, 1, 250 * kMs).empty());
  EXPECT_EQ(read_regs(b.bus, 0x68, 0x75, 1, 300 * kMs).size(), 1u);
  EXPECT_EQ(b.mpu.nacks(), 1u);
  EXPECT_EQ(b.bus.read(0), 0xFF);  // nobody drives SDA: the pull-ups
}

}  // namespace
}  // namespace poise::firmware_emu
