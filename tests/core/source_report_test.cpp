// Source identities: every enumerator has one wire name, the one the diagnostics carried when the
// identity was a string (msg::SourceStatus.source must not change), and no two share it.
#include "poise/core/source_report.h"

#include <gtest/gtest.h>

#include <cstring>
#include <map>
#include <set>
#include <string>

namespace poise {
namespace {

// Oracle: the names the cores wrote before the typed identity (source_named("...")), and the
// selective EKF's aid names (its former to_string).
const std::map<Source, std::string>& wire_names() {
  static const std::map<Source, std::string> names = {
      {Source::kGyro, "gyro"},
      {Source::kYawRate, "yaw_rate"},
      {Source::kAccel, "accel"},
      {Source::kAccelTilt, "accel_tilt"},
      {Source::kMag, "mag"},
      {Source::kMagHeading, "mag_heading"},
      {Source::kImuQuat, "imu_quat"},
      {Source::kVisionAttitude, "vision_attitude"},
      {Source::kVisionPosition, "vision_position"},
      {Source::kBaro, "baro"},
      {Source::kSpeed, "speed"},
      {Source::kZupt, "zupt"},
      {Source::kZeroRate, "zero_rate"},
  };
  return names;
}

TEST(SourceIdentity, GivenEverySourceThenItsWireNameIsTheOneTheDiagnosticsCarried) {
  const auto count = static_cast<std::size_t>(Source::kCount);
  ASSERT_EQ(wire_names().size(), count) << "a new Source needs its wire name in this oracle";
  std::set<std::string> seen;
  for (std::size_t i = 0; i < count; ++i) {
    const auto s = static_cast<Source>(i);
    EXPECT_EQ(to_string(s), wire_names().at(s));
    EXPECT_TRUE(seen.insert(to_string(s)).second) << "two sources named " << to_string(s);
    EXPECT_LE(std::strlen(to_string(s)), 32U) << "over the bound of SourceStatus.source (string<32>)";
  }
  EXPECT_STREQ(to_string(Source::kCount), "unknown");
}

TEST(SourceIdentity, GivenANewReportThenItNamesItsSourceAndWasNeverFused) {
  const SourceReport r(Source::kMagHeading);
  EXPECT_EQ(r.source, Source::kMagHeading);
  EXPECT_EQ(r.decision, SourceDecision::kNotAvailable);
  EXPECT_FALSE(r.fused());
  EXPECT_EQ(r.last_fused_stamp_ns, -1);
}

}  // namespace
}  // namespace poise
