// The GY-87 firmware's AVR binary (the ELF arduino-mk builds for the Uno) run on simavr with
// datasheet models of its sensors fed from a known motion; its UART is a pty that `poise imu`
// (a separate process) reads; this test subscribes to what the driver publishes over DDS.
// Oracle: for every published sample, the values the models held when the firmware read them
// (SI, body frame: the GY-87's chips share the body axes, the driver's default imu_axes and
// mag_axes), within the sensors' quantisation and the sketch's printed decimals.
#include <thread>

#include "emulated_chain.h"

namespace poise::firmware_emu {
namespace {

using namespace test_chain;

void run_variant(MagVariant variant) {
  // GIVEN a GY-87 with `variant` moving from power-on, `poise imu` reading its port
  EmulatorOptions o;
  o.mag = variant;
  Chain chain(o, to_string(variant));
  chain.start_driver();
  // WHEN the board runs for 3 s
  chain.board().run_for(3.0);
  chain.settle();
  // THEN every sample equals what the models held, the driver rejected nothing, and the firmware
  // broke no datasheet rule
  chain.expect_samples_equal_the_model(to_string(variant));
  EXPECT_EQ(chain.counter("rejected_total"), 0u) << chain.driver_output();
  EXPECT_EQ(chain.counter("samples_without_mag"), 0u);
  chain.expect_no_violations();
  std::printf("[ figures  ] %s: 3.0 s emulated in %.2f s; stack + heap peak %d B, static RAM %d B\n",
              to_string(variant), chain.board().host_seconds(), chain.board().stack_peak_bytes(),
              chain.board().static_ram_bytes());
}

TEST(EmulatedGy87, GivenAnHmc5883lBoardThenEverySampleThroughPoiseImuEqualsTheModelsWithinQuantisation) {
  REQUIRE_FIRMWARE();
  run_variant(MagVariant::kHmc5883l);
}

TEST(EmulatedGy87, GivenAQmc5883lCloneThenEverySampleThroughPoiseImuEqualsTheModelsWithinQuantisation) {
  REQUIRE_FIRMWARE();
  run_variant(MagVariant::kQmc5883l);
}

TEST(EmulatedGy87, GivenNoMagnetometerOrAnUnknownOneAt0x2CThenTheFirmwareSaysSoAndTheDriverPublishesWithoutMag) {
  REQUIRE_FIRMWARE();
  for (const MagVariant v : {MagVariant::kNone, MagVariant::kUnknownAt0x2C}) {
    SCOPED_TRACE(to_string(v));
    // GIVEN a board without a magnetometer the firmware knows
    EmulatorOptions o;
    o.mag = v;
    Chain chain(o, to_string(v));
    chain.start_driver();
    // WHEN it runs for 1.5 s
    chain.board().run_for(1.5);
    chain.settle();
    // THEN the firmware warns once and sends empty mag fields; the driver publishes every sample
    // with valid.mag = false and counts them
    const std::string text = chain.board().uart_text();
    EXPECT_EQ(count_of(text, "# warning: no magnetometer"), 1u) << text.substr(0, 400);
    chain.expect_samples_equal_the_model(to_string(v));
    EXPECT_EQ(chain.counter("samples_without_mag"), chain.counter("samples"));
    EXPECT_GT(chain.counter("samples"), 100u);
    EXPECT_EQ(chain.counter("rejected_total"), 0u);
    chain.expect_no_violations();
    std::printf("[ figures  ] %s: firmware: \"# warning: no magnetometer ...\"; driver: samples %lu, "
                "samples_without_mag %lu, info_lines %lu\n",
                to_string(v), static_cast<unsigned long>(chain.counter("samples")),
                static_cast<unsigned long>(chain.counter("samples_without_mag")),
                static_cast<unsigned long>(chain.counter("info_lines")));
  }
}

TEST(EmulatedGy87, GivenSensorsThatStopAnsweringMidRunThenTheFirmwareSaysSoAndTheDriverCountsTheGaps) {
  REQUIRE_FIRMWARE();
  // GIVEN the MPU6050, the HMC5883L and the BMP180 each NACKing their address for 0.3 s
  EmulatorOptions o;
  o.nack_windows = {{"MPU6050", 1.0, 1.3}, {"HMC5883L", 1.6, 1.9}, {"BMP180", 2.2, 2.5}};
  Chain chain(o, "nack");
  chain.start_driver();
  // WHEN the board runs for 3.2 s
  chain.board().run_for(3.2);
  chain.settle();
  // THEN the firmware reports each: an error line per lost MPU6050 sample (seq still counts),
  // and empty mag / pressure fields (never the stale values) until the sensor answers again
  const std::string text = chain.board().uart_text();
  const std::size_t mpu_errors = count_of(text, "# error: MPU6050 read failed");
  EXPECT_EQ(mpu_errors, chain.board().nacks("MPU6050"));
  EXPECT_NEAR(static_cast<double>(mpu_errors), 30.0, 1.0);  // 0.3 s at 100 Hz
  EXPECT_EQ(count_of(text, "# error: magnetometer not answering"), 1u);
  EXPECT_EQ(count_of(text, "# error: BMP180 not answering"), 1u);
  chain.expect_samples_equal_the_model("nack");
  // AND the driver counts the lost MPU6050 samples as a seq gap and the mag-less samples
  std::size_t without_mag = 0, without_p = 0;
  for (const LineRecord& r : chain.board().lines()) {
    without_mag += r.has_mag ? 0 : 1;
    without_p += r.has_pressure ? 0 : 1;
  }
  EXPECT_EQ(chain.counter("dropped_seq_gap"), mpu_errors);
  EXPECT_EQ(chain.counter("samples_without_mag"), without_mag);
  EXPECT_EQ(chain.counter("rejected_total"), 0u);
  EXPECT_GE(chain.counter("info_lines"), mpu_errors + 2);
  chain.expect_no_violations();
  std::printf("[ figures  ] NACK windows 0.3 s each: firmware sent %zu MPU6050 error lines, one mag and "
              "one BMP180 error line; driver: dropped_seq_gap %lu, samples_without_mag %lu, "
              "%zu samples without pressure, info_lines %lu, rejected_total %lu\n",
              mpu_errors, static_cast<unsigned long>(chain.counter("dropped_seq_gap")),
              static_cast<unsigned long>(chain.counter("samples_without_mag")), without_p,
              static_cast<unsigned long>(chain.counter("info_lines")),
              static_cast<unsigned long>(chain.counter("rejected_total")));
}

TEST(EmulatedGy87, GivenPowerOnWhileMovingThenTheFirstSampleAlreadyCarriesTheMotion) {
  REQUIRE_FIRMWARE();
  // GIVEN a board rotating and accelerating from the instant it is powered, the port open
  EmulatorOptions o;
  o.scenario = "moving";
  o.seed = 7;
  Chain chain(o, "moving");
  chain.start_driver();
  // WHEN it runs for 1 s
  chain.board().run_for(1.0);
  chain.settle();
  // THEN no sensor was read before it was ready (gyro start-up, first magnetometer measurement),
  // and the first sample the driver publishes (seq 0) is the motion at that instant
  chain.expect_no_violations();
  const auto got = chain.samples();
  ASSERT_EQ(got.count(0u), 1u) << chain.driver_output();
  const auto& first = got.at(0u);
  const double rate = std::hypot(first.gyro_rps().x(), first.gyro_rps().y(), first.gyro_rps().z());
  EXPECT_GT(rate, 0.05) << "the board is turning";
  EXPECT_TRUE(first.valid().mag());
  chain.expect_samples_equal_the_model("moving from power-on");
  const auto lines = chain.board().lines();
  ASSERT_FALSE(lines.empty());
  std::printf("[ figures  ] moving from power-on: first sample at %.1f ms after power-on, |gyro| %.3f rad/s\n",
              static_cast<double>(lines.front().imu.t_ns) * 1e-6, rate);
}

void run_open_while_streaming(bool reset_on_open) {
  // GIVEN a board streaming for 1 s with nobody reading its port
  EmulatorOptions o;
  o.reset_on_open = reset_on_open;
  Chain chain(o, reset_on_open ? "open-reset" : "open-noreset");
  chain.board().run_for(1.0);
  // WHEN `poise imu` opens it while it goes on streaming (until the driver has 150 samples)
  std::thread board([&] { chain.board().run_for(30.0); });
  chain.start_driver(false);
  EXPECT_TRUE(poise::testing::wait_until([&] { return chain.counter("samples") >= 150; }, 30s))
      << chain.driver_output();
  chain.board().stop();
  board.join();
  chain.settle();
  // (what reached the driver: the lines written after it opened the port)
  LineRecord first;
  for (const LineRecord& r : chain.board().lines()) {
    if (r.delivered) {
      first = r;
      break;
    }
  }
  const auto got = chain.samples();
  ASSERT_FALSE(got.empty()) << chain.driver_output();
  const std::string text = chain.board().uart_text();
  EXPECT_GE(chain.counter("samples"), 150u);
  EXPECT_EQ(chain.counter("dropped_seq_gap"), 0u);
  if (reset_on_open) {
    // THEN an Uno resets (DTR): the firmware starts again (banner, seq from 0) with the sensors
    // still configured from before; the driver may see the tail of the line the reset cut (the
    // bytes the USB chip still held) and the banner after it as one garbage line, then every
    // sample from seq 0
    EXPECT_EQ(chain.board().boots(), 1);
    EXPECT_EQ(count_of(text, "# gy87_poise v1 ready"), 2u);
    EXPECT_EQ(first.boot, 1);
    EXPECT_EQ(first.seq, 0u);
    EXPECT_GE(chain.counter("info_lines"), 1u);
    EXPECT_LE(chain.counter("rejected_total"), 1u);
  } else {
    // THEN a board without the auto-reset is joined mid-stream: at most the cut line is lost
    // (counted as garbage or truncated), the rest is published from the seq it had reached
    EXPECT_EQ(chain.board().boots(), 0);
    EXPECT_EQ(first.boot, 0);
    EXPECT_GT(first.seq, 50u);
    EXPECT_LE(chain.counter("rejected_total"), 1u);
    EXPECT_EQ(chain.counter("info_lines"), 0u);
  }
  // (the driver may publish before this test's reader is matched: counted from the first received)
  chain.expect_samples_equal_the_model(reset_on_open ? "opened, Uno reset" : "opened, no reset", true);
  chain.expect_no_violations();
  std::printf("[ figures  ] port opened after 1 s (%s): first whole line seq %u, driver rejected_total %lu "
              "(garbage %lu, truncated %lu), info_lines %lu, sensor_restarts %lu\n",
              reset_on_open ? "Uno auto-reset" : "no reset", first.seq,
              static_cast<unsigned long>(chain.counter("rejected_total")),
              static_cast<unsigned long>(chain.counter("rejected_garbage")),
              static_cast<unsigned long>(chain.counter("rejected_truncated")),
              static_cast<unsigned long>(chain.counter("info_lines")),
              static_cast<unsigned long>(chain.counter("sensor_restarts")));
}

TEST(EmulatedGy87, GivenTheBoardStreamingWhenAnUnoIsOpenedThenItRestartsAndTheDriverSeesACleanStart) {
  REQUIRE_FIRMWARE();
  run_open_while_streaming(true);
}

TEST(EmulatedGy87, GivenTheBoardStreamingWhenABoardWithoutAutoResetIsOpenedThenTheDriverJoinsMidStream) {
  REQUIRE_FIRMWARE();
  run_open_while_streaming(false);
}

}  // namespace
}  // namespace poise::firmware_emu
