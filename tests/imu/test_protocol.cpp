// Parser golden lines: one test per rejection reason plus the accepted variants.
#include <gtest/gtest.h>

#include <string>

#include "poise/imu/protocol.h"

namespace poise::imu {
namespace {

constexpr double kExactTol = 1e-12;          // values parsed from decimal text, relative units
constexpr double kCountTol = 1e-9;           // SI values converted from integer counts

// A valid line whose payload is given without '$' and '*CS'.
std::string line(const std::string& payload) {
  std::string l = wrap_payload(payload);
  l.resize(l.size() - 2);  // the parser gets lines without "\r\n"
  return l;
}

const char* kGood = "IMU,42,1000000,0.1,-0.2,9.81,0.01,-0.02,0.03,20.5,-3.25,-40,101325.0,24.5";

ParseResult parse(const std::string& l) { return LineParser().parse(l); }

void expect_reject(const std::string& l, RejectReason r) {
  const ParseResult res = parse(l);
  EXPECT_FALSE(res.ok) << l;
  EXPECT_EQ(res.reason, r) << l << " -> " << to_string(res.reason);
}

TEST(ImuProtocol, ChecksumIsXorBetweenDollarAndStar) {
  // GIVEN the NMEA reference sentence (its published checksum is 0x47)
  // THEN the XOR of the payload matches
  EXPECT_EQ(nmea_checksum("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"), 0x47);
  EXPECT_EQ(wrap_payload("A"), "$A*41\r\n");
}

TEST(ImuProtocol, AcceptsSiLineWithAllFields) {
  const ParseResult r = parse(line(kGood));
  ASSERT_TRUE(r.ok) << to_string(r.reason);
  EXPECT_EQ(r.sample.seq, 42u);
  EXPECT_EQ(r.sample.t_us, 1000000u);
  EXPECT_NEAR(r.sample.accel_mps2.z(), 9.81, kExactTol);
  EXPECT_NEAR(r.sample.gyro_rps.y(), -0.02, kExactTol);
  EXPECT_NEAR(r.sample.mag_ut.z(), -40.0, kExactTol);
  EXPECT_TRUE(r.sample.has_pressure);
  EXPECT_NEAR(r.sample.pressure_pa, 101325.0, kExactTol);
  EXPECT_TRUE(r.sample.has_temperature);
  EXPECT_NEAR(r.sample.temperature_c, 24.5, kExactTol);
  EXPECT_FALSE(r.sample.from_raw_counts);
}

TEST(ImuProtocol, AcceptsEmptyPressureAndTemperatureAndCarriageReturn) {
  const ParseResult r = parse(line("IMU,1,2,0,0,9.8,0,0,0,1,2,3,,") + "\r");
  ASSERT_TRUE(r.ok) << to_string(r.reason);
  EXPECT_FALSE(r.sample.has_pressure);
  EXPECT_FALSE(r.sample.has_temperature);
}

TEST(ImuProtocol, AcceptsLowercaseChecksumAndExponentsAndPlusSign) {
  std::string l = line("IMU,1,2,1e-3,+2.5E1,-0,0,0,0,1,2,3,,");
  for (char& c : l) {
    if (c >= 'A' && c <= 'F' && &c > &l[l.find('*')]) c = static_cast<char>(c - 'A' + 'a');
  }
  const ParseResult r = parse(l);
  ASSERT_TRUE(r.ok) << to_string(r.reason);
  EXPECT_NEAR(r.sample.accel_mps2.x(), 1e-3, kExactTol);
  EXPECT_NEAR(r.sample.accel_mps2.y(), 25.0, kExactTol);
}

TEST(ImuProtocol, RawCountsAreConvertedWithTheConfiguredScales) {
  // GIVEN MPU6050 +-2 g / 250 dps, HMC5883L gain 1090 LSB/Ga
  RawCounts c;
  c.seq = 7;
  c.t_us = 123;
  c.accel = {0, 0, 16384};
  c.gyro = {131, -262, 0};
  c.mag = {1090, 0, -545};
  c.has_pressure = true;
  c.pressure_pa = 100000;
  c.has_temperature = true;
  c.temperature = -340;
  std::string l = format_raw_line(c);
  l.resize(l.size() - 2);
  const ParseResult r = parse(l);
  ASSERT_TRUE(r.ok) << to_string(r.reason);
  EXPECT_TRUE(r.sample.from_raw_counts);
  EXPECT_NEAR(r.sample.accel_mps2.z(), 9.80665, kCountTol);
  EXPECT_NEAR(r.sample.gyro_rps.x(), 3.14159265358979 / 180.0, kCountTol);
  EXPECT_NEAR(r.sample.gyro_rps.y(), -2.0 * 3.14159265358979 / 180.0, kCountTol);
  EXPECT_NEAR(r.sample.mag_ut.x(), 100.0, kCountTol);  // 1 gauss = 100 uT
  EXPECT_NEAR(r.sample.mag_ut.z(), -50.0, kCountTol);
  EXPECT_NEAR(r.sample.pressure_pa, 100000.0, kCountTol);
  EXPECT_NEAR(r.sample.temperature_c, 36.53 - 1.0, kCountTol);
}

TEST(ImuProtocol, FormatThenParseRoundTrips) {
  RawSample s;
  s.seq = 4294967295u;
  s.t_us = 4294967000u;
  s.accel_mps2 = {1.5, -2.25, 9.75};
  s.gyro_rps = {0.125, -0.5, 1.0};
  s.mag_ut = {10.0, -20.0, 30.5};
  s.has_temperature = true;
  s.temperature_c = 21.25;
  std::string l = format_imu_line(s);
  l.resize(l.size() - 2);
  const ParseResult r = parse(l);
  ASSERT_TRUE(r.ok) << to_string(r.reason);
  EXPECT_EQ(r.sample.seq, s.seq);
  EXPECT_EQ(r.sample.t_us, s.t_us);
  EXPECT_TRUE(r.sample.accel_mps2.isApprox(s.accel_mps2));
  EXPECT_TRUE(r.sample.mag_ut.isApprox(s.mag_ut));
  EXPECT_FALSE(r.sample.has_pressure);
}

TEST(ImuProtocolReject, Garbage) { expect_reject("hello world", RejectReason::kGarbage); }

TEST(ImuProtocolReject, Overlong) {
  expect_reject(line(std::string(kGood) + std::string(300, '0')), RejectReason::kOverlong);
}

TEST(ImuProtocolReject, TruncatedWithoutChecksum) {
  expect_reject("$IMU,42,1000000,0.1,-0.2,9.8", RejectReason::kTruncated);
  expect_reject(line(kGood).substr(0, line(kGood).size() - 1), RejectReason::kTruncated);
}

TEST(ImuProtocolReject, BadChecksumField) {
  std::string l = line(kGood);
  l[l.size() - 1] = 'G';
  expect_reject(l, RejectReason::kBadChecksumField);
  expect_reject(line(kGood) + "0", RejectReason::kBadChecksumField);
}

TEST(ImuProtocolReject, ChecksumMismatch) {
  std::string l = line(kGood);
  l[8] = static_cast<char>(l[8] ^ 0x01);  // one bit flipped in the payload
  expect_reject(l, RejectReason::kChecksumMismatch);
}

TEST(ImuProtocolReject, UnknownSentence) {
  expect_reject(line("GPGGA,1,2"), RejectReason::kUnknownSentence);
  expect_reject(line("IMUX,1,2,0,0,9.8,0,0,0,1,2,3,,"), RejectReason::kUnknownSentence);
}

TEST(ImuProtocolReject, FieldCount) {
  expect_reject(line("IMU,1,2,0,0,9.8,0,0,0,1,2,3,"), RejectReason::kFieldCount);
  expect_reject(line("IMU,1,2,0,0,9.8,0,0,0,1,2,3,,,"), RejectReason::kFieldCount);
  expect_reject(line("IMU"), RejectReason::kFieldCount);
}

TEST(ImuProtocolReject, MissingMandatoryField) {
  expect_reject(line("IMU,1,2,0,,9.8,0,0,0,1,2,3,,"), RejectReason::kMissingField);
  expect_reject(line("IMU,,2,0,0,9.8,0,0,0,1,2,3,,"), RejectReason::kMissingField);
}

TEST(ImuProtocolReject, NonNumeric) {
  expect_reject(line("IMU,1,2,0,abc,9.8,0,0,0,1,2,3,,"), RejectReason::kNonNumeric);
  expect_reject(line("IMU,1,2,0,1.5x,9.8,0,0,0,1,2,3,,"), RejectReason::kNonNumeric);
  expect_reject(line("IMU,-1,2,0,0,9.8,0,0,0,1,2,3,,"), RejectReason::kNonNumeric);
  expect_reject(line("IMU,1,2, 0,0,9.8,0,0,0,1,2,3,,"), RejectReason::kNonNumeric);
  expect_reject(line("RAW,1,2,0,0.5,16384,0,0,0,1,2,3,,"), RejectReason::kNonNumeric);
}

TEST(ImuProtocolReject, NotFinite) {
  expect_reject(line("IMU,1,2,0,0,nan,0,0,0,1,2,3,,"), RejectReason::kNotFinite);
  expect_reject(line("IMU,1,2,0,0,9.8,inf,0,0,1,2,3,,"), RejectReason::kNotFinite);
  expect_reject(line("IMU,1,2,0,0,9.8,0,0,0,1,2,3,NaN,"), RejectReason::kNotFinite);
}

TEST(ImuProtocolReject, OutOfRange) {
  expect_reject(line("IMU,1,2,0,0,500,0,0,0,1,2,3,,"), RejectReason::kOutOfRange);      // accel
  expect_reject(line("IMU,1,2,0,0,9.8,0,0,99,1,2,3,,"), RejectReason::kOutOfRange);     // gyro
  expect_reject(line("IMU,1,2,0,0,9.8,0,0,0,1,2,3000,,"), RejectReason::kOutOfRange);   // mag
  expect_reject(line("IMU,1,2,0,0,9.8,0,0,0,1,2,3,5,"), RejectReason::kOutOfRange);     // pressure
  expect_reject(line("IMU,1,2,0,0,9.8,0,0,0,1,2,3,,300"), RejectReason::kOutOfRange);   // temp
  expect_reject(line("IMU,4294967296,2,0,0,9.8,0,0,0,1,2,3,,"), RejectReason::kOutOfRange);
  expect_reject(line("IMU,1,2,1e999,0,9.8,0,0,0,1,2,3,,"), RejectReason::kOutOfRange);
  expect_reject(line("RAW,1,2,0,0,40000,0,0,0,1,2,3,,"), RejectReason::kOutOfRange);    // int16
}

TEST(ImuProtocol, EmptyOrSaturatedMagnetometerFlagsTheSampleInsteadOfDroppingIt) {
  ParseResult r = parse(line("IMU,1,2,0,0,9.8,0,0,0,,,,,"));
  ASSERT_TRUE(r.ok) << to_string(r.reason);
  EXPECT_FALSE(r.sample.has_mag);
  r = parse(line("RAW,1,2,0,0,16384,0,0,0,-4096,2,3,,"));  // HMC5883L overflow on x
  ASSERT_TRUE(r.ok) << to_string(r.reason);
  EXPECT_FALSE(r.sample.has_mag);
  EXPECT_NEAR(r.sample.accel_mps2.z(), 9.80665, kCountTol);
  expect_reject(line("IMU,1,2,0,0,9.8,0,0,0,1,,,,"), RejectReason::kMissingField);  // partial mag
}

TEST(ImuProtocol, EveryReasonHasADistinctName) {
  for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
    for (std::size_t j = i + 1; j < kRejectReasonCount; ++j) {
      EXPECT_STRNE(to_string(static_cast<RejectReason>(i)), to_string(static_cast<RejectReason>(j)));
    }
  }
}

}  // namespace
}  // namespace poise::imu
