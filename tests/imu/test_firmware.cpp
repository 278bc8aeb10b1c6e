// The reference sketch (tools/firmware/gy87_poise) run on the host against a simulated GY-87
// (I2C register model): every line it prints is accepted by the driver with the right values,
// and its BMP180 compensation reproduces the datasheet's worked example.
#include <gtest/gtest.h>

#include <vector>

#include "poise/imu/driver.h"
// The host-side Arduino mocks last: Arduino's F() macro would clash with Eigen.
#include "Arduino.h"
#include "Wire.h"
#undef F

void setup();
void loop();

namespace poise::imu {
namespace {

constexpr double kPi = 3.14159265358979323846;

void put16(uint8_t addr, uint8_t reg, int v) {
  Wire.regs[addr][reg] = static_cast<uint8_t>((v >> 8) & 0xFF);
  Wire.regs[addr][static_cast<uint8_t>(reg + 1)] = static_cast<uint8_t>(v & 0xFF);
}

void run_sketch_and_check() {
  // GIVEN a GY-87: MPU6050 at +-4 g / 500 dps, HMC5883L gain 1090, BMP180 with the datasheet's
  // example calibration (UT 27898, UP 23843, oss 0 -> 15.0 C, 69964 Pa)
  for (const uint8_t a : {0x68, 0x1E, 0x77}) Wire.present[a] = true;
  Wire.regs[0x68][0x75] = 0x68;
  Wire.regs[0x1E][0x0A] = 'H';
  Wire.regs[0x1E][0x0B] = '4';
  Wire.regs[0x1E][0x0C] = '3';
  Wire.regs[0x77][0xD0] = 0x55;
  const int cal[11] = {408, -72, -14383, 32741, 32757, 23153, 6190, 4, -32768, -8711, 2868};
  for (int i = 0; i < 11; ++i) put16(0x77, static_cast<uint8_t>(0xAA + 2 * i), cal[i]);
  Wire.bmp_ut = 27898;
  Wire.bmp_up = 23843;
  put16(0x68, 0x3B, 0);      // ax
  put16(0x68, 0x3D, 4096);   // ay = 0.5 g
  put16(0x68, 0x3F, 8192);   // az = 1 g
  put16(0x68, 0x41, -1000);  // TEMP_OUT -> 33.59 C
  put16(0x68, 0x43, 655);    // gx = 10 dps
  put16(0x68, 0x45, -131);   // gy = -2 dps
  put16(0x68, 0x47, 0);      // gz
  put16(0x1E, 0x03, 545);    // X = 0.5 Ga = 50 uT
  put16(0x1E, 0x05, -1090);  // Z (the chip's order is X, Z, Y) = -100 uT
  put16(0x1E, 0x07, 109);    // Y = 10 uT
  // WHEN the sketch runs for 0.3 s
  setup();
  for (int i = 0; i < 600; ++i) {
    mock_micros_now += 500;
    loop();
  }
  // THEN the driver accepts every line, with the register values in SI units
  DriverParams params;
  params.raw.accel_lsb_per_g = 8192.0;
  params.raw.gyro_lsb_per_dps = 65.5;
  std::vector<ImuSample> out;
  std::vector<SampleInfo> info;
  ImuDriver driver(params, {}, [&](const ImuSample& s, const SampleInfo& i) {
    out.push_back(s);
    info.push_back(i);
  });
  driver.feed(Serial.out, 1'000'000'000);
  EXPECT_EQ(driver.stats().rejected_total(), 0u) << Serial.out.substr(0, 400);
  EXPECT_EQ(driver.stats().last_info, "# gy87_poise v1 ready");
  // the sketch says its DLPF setting ($INF at start): the driver knows the datasheet's delay
  ASSERT_TRUE(driver.sensor_delay()) << Serial.out.substr(0, 400);
  EXPECT_EQ(driver.sensor_delay()->setting, 3);
  EXPECT_NEAR(driver.sensor_delay()->gyro_delay_s, 4.8e-3, 1e-12);
  ASSERT_GE(out.size(), 25u) << Serial.out.substr(0, 400);
  EXPECT_EQ(driver.stats().seq_gap_drops, 0u);
  constexpr double kAccelTol = 2e-3;   // 3 decimals (SI) or one count (raw), m/s^2
  constexpr double kGyroTol = 2e-4;    // rad/s
  constexpr double kMagTol = 0.1;      // uT
  const double g = 9.80665;
  const ImuSample& s = out.back();
  EXPECT_NEAR(s.accel_mps2.x(), 0.0, kAccelTol);
  EXPECT_NEAR(s.accel_mps2.y(), 0.5 * g, kAccelTol);
  EXPECT_NEAR(s.accel_mps2.z(), g, kAccelTol);
  EXPECT_NEAR(s.gyro_rps.x(), 655.0 / 65.5 * kPi / 180.0, kGyroTol);
  EXPECT_NEAR(s.gyro_rps.y(), -131.0 / 65.5 * kPi / 180.0, kGyroTol);
  ASSERT_TRUE(s.has_mag);
  EXPECT_NEAR(s.mag_ut.x(), 50.0, kMagTol);
  EXPECT_NEAR(s.mag_ut.y(), 10.0, kMagTol);
  EXPECT_NEAR(s.mag_ut.z(), -100.0, kMagTol);
  ASSERT_TRUE(s.has_pressure);
  EXPECT_DOUBLE_EQ(s.pressure_pa, 69964.0);  // Bosch BMP180 datasheet, section 3.5 example
  ASSERT_TRUE(s.has_temperature);
  EXPECT_NEAR(s.temperature_c, -1000.0 / 340.0 + 36.53, 0.01);
  // One sample per SAMPLE_PERIOD_US (10 ms) on the sensor clock (the loop polls every 500 us
  // here, so the first sample after setup() may come up to one poll late).
  constexpr uint32_t kLoopPollUs = 500;
  for (std::size_t i = 1; i < info.size(); ++i) {
    EXPECT_NEAR(static_cast<double>(info[i].raw.t_us - info[i - 1].raw.t_us), 10000.0, kLoopPollUs);
    EXPECT_EQ(info[i].raw.seq, info[i - 1].raw.seq + 1);
  }
}

// One executable per sketch output format (OUTPUT_RAW), each with its own test name.
#if defined(IMU_FIRMWARE_RAW)
TEST(ImuFirmwareRaw, SketchOutputIsAcceptedWithTheRegisterValues) { run_sketch_and_check(); }
#else
TEST(ImuFirmwareSi, SketchOutputIsAcceptedWithTheRegisterValues) { run_sketch_and_check(); }
#endif

}  // namespace
}  // namespace poise::imu
