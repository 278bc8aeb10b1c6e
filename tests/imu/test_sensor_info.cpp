// The $INF sensor info line (docs/SERIAL_PROTOCOL.md "Sensor info"): the MPU6050's DLPF table,
// the parser and the driver, hostile lines counted by reason with a message.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "poise/imu/driver.h"
#include "poise/imu/sensor_info.h"

namespace poise::imu {
namespace {

constexpr double kTableTolS = 1e-12;  // figures typed from the register map, s

std::string line(const std::string& payload) { return wrap_payload(payload); }

std::string imu_line(uint32_t seq) {
  RawSample s;
  s.seq = seq;
  s.t_us = 1000 + seq * 10000;
  s.accel_mps2 = {0, 0, 9.81};
  s.has_mag = false;
  return format_imu_line(s);
}

TEST(Mpu6050Dlpf, GivenTheRegisterMapTableThenEverySettingGivesItsDatasheetDelayAndSevenIsRefused) {
  // GIVEN the register map rev 4.2, register 26, DLPF_CFG table (typed here from the datasheet:
  // accel delay ms, gyro delay ms)
  const double expected[7][2] = {{0.0, 0.98}, {2.0, 1.9}, {3.0, 2.8}, {4.9, 4.8}, {8.5, 8.3}, {13.8, 13.4}, {19.0, 18.6}};
  for (int cfg = 0; cfg < 7; ++cfg) {
    // WHEN a setting is resolved from a $INF line without delays
    SensorInfoLine l;
    l.version = 1;
    l.chip = "MPU6050";
    l.setting = cfg;
    const InfoResolution r = resolve_sensor_info(l);
    // THEN its delays are the datasheet's, from the driver's table
    ASSERT_TRUE(r.delay) << cfg << ": " << r.message;
    EXPECT_NEAR(r.delay->accel_delay_s, expected[cfg][0] * 1e-3, kTableTolS) << cfg;
    EXPECT_NEAR(r.delay->gyro_delay_s, expected[cfg][1] * 1e-3, kTableTolS) << cfg;
    EXPECT_EQ(r.delay->origin, "table");
  }
  EXPECT_EQ(mpu6050_dlpf(7), nullptr);
  EXPECT_EQ(mpu6050_dlpf(-1), nullptr);
}

TEST(ImuSensorInfo, GivenTheFirmwareInfoLineWhenParsedThenItsFieldsAreKeptAndFormatRoundTrips) {
  SensorInfoLine l;
  l.version = 1;
  l.chip = "MPU6050";
  l.setting = 3;
  const std::string text = format_info_line(l);
  EXPECT_EQ(text.substr(0, 18), "$INF,1,MPU6050,3,,");
  std::string bare = text;
  bare.resize(bare.size() - 2);
  const ParseResult r = LineParser().parse(bare);
  ASSERT_TRUE(r.ok) << to_string(r.reason);
  ASSERT_TRUE(r.is_info);
  EXPECT_EQ(r.info.chip, "MPU6050");
  EXPECT_EQ(r.info.setting, 3);
  EXPECT_FALSE(r.info.has_delays);
}

// Every hostile $INF line: refused under one reason, never a sample, never a crash.
TEST(ImuSensorInfo, GivenHostileInfoLinesWhenFedThenEachIsCountedUnderItsReasonWithAMessage) {
  struct Case {
    const char* payload;
    RejectReason reason;
  };
  const std::vector<Case> cases{
      {"INF,1,MPU6050,7,,", RejectReason::kInfoUnknownSetting},   // reserved setting
      {"INF,1,MPU6050,12,,", RejectReason::kInfoUnknownSetting},  // not in the table
      {"INF,1,MPU6050,x3,,", RejectReason::kNonNumeric},          // garbage setting
      {"INF,1,MPU6050,3.0,,", RejectReason::kNonNumeric},
      {"INF,1,MPU6050,-1,,", RejectReason::kOutOfRange},
      {"INF,1,MPU6050,3,4900,1000", RejectReason::kInfoConflict},  // delays against the table
      {"INF,2,MPU6050,3,,", RejectReason::kInfoUnsupported},       // a later version
      {"INF,x,MPU6050,3,,", RejectReason::kNonNumeric},
      {"INF,1,MPU 6050,3,,", RejectReason::kInfoUnsupported},      // chip name characters
      {"INF,1,,3,,", RejectReason::kMissingField},
      {"INF,1,BMI270,,,", RejectReason::kMissingField},            // neither setting nor delays
      {"INF,1,BMI270,2,,", RejectReason::kInfoUnknownSetting},     // unknown chip, no delays
      {"INF,1,BMI270,2,1000,", RejectReason::kMissingField},       // one delay only
      {"INF,1,BMI270,2,1000,60000", RejectReason::kOutOfRange},    // beyond 50 ms
      {"INF,1,MPU6050,3,,,", RejectReason::kFieldCount},
      {"INF,1,MPU6050", RejectReason::kFieldCount},
      {"INF", RejectReason::kFieldCount},
  };
  for (const Case& c : cases) {
    std::vector<std::string> problems;
    int samples = 0;
    ImuDriver d({}, {}, [&](const ImuSample&, const SampleInfo&) { ++samples; });
    d.set_info_problem_sink([&](const std::string& m) { problems.push_back(m); });
    d.feed(line(c.payload) + imu_line(0), 1'000'000'000);
    EXPECT_EQ(d.stats().rejects[static_cast<std::size_t>(c.reason)], 1u)
        << c.payload << " -> expected " << to_string(c.reason);
    EXPECT_EQ(d.stats().rejected_total(), 1u) << c.payload;
    EXPECT_FALSE(d.sensor_delay()) << c.payload;
    EXPECT_EQ(samples, 1) << c.payload;  // the samples are unaffected
    const bool semantic = c.reason == RejectReason::kInfoUnknownSetting || c.reason == RejectReason::kInfoConflict;
    if (semantic) {  // a refusal of a well-formed line says why
      ASSERT_EQ(problems.size(), 1u) << c.payload;
      EXPECT_NE(problems[0].find("$INF"), std::string::npos) << problems[0];
      EXPECT_EQ(d.stats().last_info_problem, problems[0]);
    }
  }
}

TEST(ImuSensorInfo, GivenTheGy87InfoThenSamplesWhenFedThenTheDelayIsKnownOnceAndRepeatsAreNotNews) {
  // GIVEN the firmware's start: its info line, samples, the periodic repeat
  std::vector<SensorDelay> told;
  int samples = 0;
  ImuDriver d({}, {}, [&](const ImuSample&, const SampleInfo&) { ++samples; });
  d.set_delay_sink([&](const SensorDelay& s) { told.push_back(s); });
  std::string bytes = line("INF,1,MPU6050,3,,");
  for (uint32_t k = 0; k < 5; ++k) bytes += imu_line(k);
  bytes += line("INF,1,MPU6050,3,,");
  // WHEN fed
  d.feed(bytes, 1'000'000'000);
  // THEN the delay is the datasheet's for DLPF_CFG 3, told once; nothing rejected
  ASSERT_TRUE(d.sensor_delay());
  EXPECT_NEAR(d.sensor_delay()->gyro_delay_s, 4.8e-3, kTableTolS);
  EXPECT_NEAR(d.sensor_delay()->accel_delay_s, 4.9e-3, kTableTolS);
  EXPECT_EQ(told.size(), 1u);
  EXPECT_EQ(d.stats().sensor_info_lines, 2u);
  EXPECT_EQ(d.stats().rejected_total(), 0u);
  EXPECT_EQ(samples, 5);
  EXPECT_NE(told[0].describe().find("4.80 ms"), std::string::npos) << told[0].describe();
}

TEST(ImuSensorInfo, GivenAConflictingSettingWithoutARestartThenRefusedAndAfterARestartTaken) {
  std::vector<SensorDelay> told;
  ImuDriver d({}, {}, nullptr);
  d.set_delay_sink([&](const SensorDelay& s) { told.push_back(s); });
  // GIVEN a sensor that said DLPF_CFG 3 and streams
  std::string bytes = line("INF,1,MPU6050,3,,");
  for (uint32_t k = 1000; k < 1003; ++k) bytes += imu_line(k);
  // WHEN it says DLPF_CFG 6 without restarting
  bytes += line("INF,1,MPU6050,6,,");
  d.feed(bytes, 1'000'000'000);
  // THEN the conflict is refused, counted and said, and the first delay stays
  EXPECT_EQ(d.stats().rejects[static_cast<std::size_t>(RejectReason::kInfoConflict)], 1u);
  EXPECT_NE(d.stats().last_info_problem.find("contradicts"), std::string::npos) << d.stats().last_info_problem;
  ASSERT_TRUE(d.sensor_delay());
  EXPECT_EQ(d.sensor_delay()->setting, 3);
  // WHEN the board restarts (seq from 0 again, beyond the reorder window: a reflash) and says 6
  // again
  d.feed(imu_line(0) + line("INF,1,MPU6050,6,,"), 1'100'000'000);
  // THEN the new setting is taken and told
  EXPECT_EQ(d.sensor_delay()->setting, 6);
  ASSERT_EQ(told.size(), 2u);
  EXPECT_NEAR(told[1].gyro_delay_s, 18.6e-3, kTableTolS);
}

TEST(ImuSensorInfo, GivenAnotherChipWithItsOwnDelaysThenTheyAreUsedAsGiven) {
  ImuDriver d({}, {}, nullptr);
  d.feed(line("INF,1,BMI270,2,2500,1700"), 1'000'000'000);
  ASSERT_TRUE(d.sensor_delay());
  EXPECT_NEAR(d.sensor_delay()->accel_delay_s, 2.5e-3, kTableTolS);
  EXPECT_NEAR(d.sensor_delay()->gyro_delay_s, 1.7e-3, kTableTolS);
  EXPECT_EQ(d.sensor_delay()->origin, "sensor");
  // and an MPU6050 line that gives the table's own figures is accepted
  ImuDriver m({}, {}, nullptr);
  m.feed(line("INF,1,MPU6050,3,4900,4800"), 1'000'000'000);
  ASSERT_TRUE(m.sensor_delay());
  EXPECT_EQ(m.stats().rejected_total(), 0u);
}

TEST(ImuSensorInfo, GivenOldFirmwareWithoutTheLineThenNoDelayIsKnownAndNothingIsRejected) {
  int samples = 0;
  ImuDriver d({}, {}, [&](const ImuSample&, const SampleInfo&) { ++samples; });
  std::string bytes = "# gy87_poise v1 ready\r\n";
  for (uint32_t k = 0; k < 5; ++k) bytes += imu_line(k);
  d.feed(bytes, 1'000'000'000);
  EXPECT_FALSE(d.sensor_delay());
  EXPECT_EQ(d.stats().rejected_total(), 0u);
  EXPECT_EQ(samples, 5);
}

}  // namespace
}  // namespace poise::imu
