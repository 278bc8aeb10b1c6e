// The ROS IMU input (components/bridges/ros2_bridge/input.h): pairing of Imu with MagneticField and
// FluidPressure streams by stamp, each at its own rate, and hostile messages rejected by reason.
// Oracles: the stamps and values the test sends.
#include "poise/ros2_bridge/input.h"

#include <gtest/gtest.h>

#include <limits>

namespace poise::ros2 {
namespace {

constexpr int64_t kPeriodNs = 5'000'000;  // 200 Hz IMU
constexpr int64_t kT0 = 10'000'000'000;    // 10 s
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

ros_time::Time_ time_of(int64_t ns) { return to_ros_time(ns, 0).value(); }

ros_sensor::Imu_ imu(int64_t ns, double gx = 0.01) {
  ros_sensor::Imu_ m;
  m.header().stamp(time_of(ns));
  m.angular_velocity().x(gx);
  m.linear_acceleration().z(9.81);
  m.orientation_covariance()[0] = -1.0;
  return m;
}
ros_sensor::MagneticField_ mag(int64_t ns, double x_tesla = 20e-6) {
  ros_sensor::MagneticField_ m;
  m.header().stamp(time_of(ns));
  m.magnetic_field().x(x_tesla);
  m.magnetic_field().z(-40e-6);
  return m;
}
ros_sensor::FluidPressure_ pressure(int64_t ns, double pa = 101000.0) {
  ros_sensor::FluidPressure_ m;
  m.header().stamp(time_of(ns));
  m.fluid_pressure(pa);
  return m;
}

InputConfig config(bool with_mag, bool with_pressure) {
  InputConfig c;
  c.mag = with_mag;
  c.pressure = with_pressure;
  return c;
}

TEST(Ros2Input, GivenImuAndMagAtTheSameStampsInEitherOrderThenEverySampleCarriesItsMag) {
  ImuAssembler a(config(true, false));
  const auto first = a.on_imu(imu(kT0));
  ASSERT_EQ(first.size(), 1U) << "no magnetometer seen yet: nothing to wait for";
  EXPECT_FALSE(first[0].has_mag);
  std::vector<ImuSample> out;
  for (int k = 1; k <= 4; ++k) {
    const int64_t t = kT0 + k * kPeriodNs;
    if (k % 2 == 0) {
      EXPECT_TRUE(a.on_imu(imu(t)).empty()) << "Imu first: held until its magnetometer arrives";
      const auto done = a.on_mag(mag(t));
      out.insert(out.end(), done.begin(), done.end());
    } else {
      EXPECT_TRUE(a.on_mag(mag(t)).empty());
      const auto done = a.on_imu(imu(t));
      out.insert(out.end(), done.begin(), done.end());
    }
  }
  ASSERT_EQ(out.size(), 4U);
  for (std::size_t k = 0; k < out.size(); ++k) {
    EXPECT_EQ(out[k].stamp_ns, kT0 + static_cast<int64_t>(k + 1) * kPeriodNs);
    EXPECT_TRUE(out[k].has_mag);
    EXPECT_DOUBLE_EQ(out[k].mag_ut.x(), 20.0) << "tesla -> microtesla";
    EXPECT_DOUBLE_EQ(out[k].mag_ut.z(), -40.0);
    EXPECT_FALSE(out[k].has_pressure);
  }
  EXPECT_EQ(a.rejected_total(), 0U);
}

TEST(Ros2Input, GivenMagAtHalfAndPressureAtAQuarterOfTheImuRateThenEachIsPairedOnceToTheNearestImu) {
  ImuAssembler a(config(true, true));
  std::vector<ImuSample> out;
  const auto take = [&out](std::vector<ImuSample> v) { out.insert(out.end(), v.begin(), v.end()); };
  for (int k = 0; k < 8; ++k) {
    const int64_t t = kT0 + k * kPeriodNs;
    if (k % 2 == 0) {
      take(a.on_mag(mag(t + 1'000'000)));  // 1 ms after the IMU sample: within tolerance
    }
    if (k % 4 == 0) {
      take(a.on_pressure(pressure(t, 100000.0 + k)));
    }
    // Odd samples wait for the side streams to pass their stamp, then go unpaired.
    take(a.on_imu(imu(t)));
  }
  take(a.on_imu(imu(kT0 + 8 * kPeriodNs)));  // releases the last one held
  ASSERT_GE(out.size(), 8U);
  for (int k = 0; k < 8; ++k) {
    SCOPED_TRACE(k);
    EXPECT_EQ(out[static_cast<std::size_t>(k)].stamp_ns, kT0 + k * kPeriodNs);
    EXPECT_EQ(out[static_cast<std::size_t>(k)].has_mag, k % 2 == 0);
    EXPECT_EQ(out[static_cast<std::size_t>(k)].has_pressure, k % 4 == 0);
    if (k % 4 == 0) {
      EXPECT_EQ(out[static_cast<std::size_t>(k)].pressure_pa, 100000.0 + k);
    }
    EXPECT_EQ(out[static_cast<std::size_t>(k)].seq, static_cast<uint32_t>(k));
  }
  EXPECT_EQ(a.paired_mag(), 4U);
  EXPECT_EQ(a.paired_pressure(), 2U);
}

TEST(Ros2Input, GivenADeadMagStreamThenImuSamplesAreNotHeld) {
  ImuAssembler a(config(true, false));
  ASSERT_TRUE(a.on_mag(mag(kT0)).empty());
  // 1 s later (stale_s 0.5 s): nothing to wait for.
  const auto out = a.on_imu(imu(kT0 + 1'000'000'000));
  ASSERT_EQ(out.size(), 1U);
  EXPECT_FALSE(out[0].has_mag);
}

TEST(Ros2Input, GivenHostileMessagesThenEachIsRejectedByReasonAndNothingNonFiniteComesOut) {
  ImuAssembler a(config(true, true));
  std::vector<ImuSample> out;
  const auto take = [&out](std::vector<ImuSample> v) { out.insert(out.end(), v.begin(), v.end()); };
  take(a.on_imu(imu(kT0, kNaN)));
  take(a.on_imu(imu(kT0, 1e9)));  // 1e9 rad/s
  auto no_gyro = imu(kT0);
  no_gyro.angular_velocity_covariance()[0] = -1.0;  // REP 145: not provided
  take(a.on_imu(no_gyro));
  auto bad_stamp = imu(kT0);
  bad_stamp.header().stamp().nanosec(1'000'000'000U);
  take(a.on_imu(bad_stamp));
  auto negative = imu(kT0);
  negative.header().stamp().sec(-5);
  take(a.on_imu(negative));
  take(a.on_imu(imu(kT0)));                  // good (no valid side sample yet: not held)
  take(a.on_imu(imu(kT0 - kPeriodNs)));      // backwards
  take(a.on_mag(mag(kT0, kNaN)));
  take(a.on_mag(mag(kT0, 1.0)));             // 1 T
  take(a.on_pressure(pressure(kT0, kNaN)));
  take(a.on_pressure(pressure(kT0, -3.0)));
  take(a.on_imu(imu(kT0 + kPeriodNs)));      // good
  const auto& r = a.rejected();
  EXPECT_EQ(r.at("imu_non_finite_gyro"), 1U);
  EXPECT_EQ(r.at("imu_gyro_out_of_range"), 1U);
  EXPECT_EQ(r.at("imu_missing_gyro"), 1U);
  EXPECT_EQ(r.at("imu_bad_stamp"), 2U);
  EXPECT_EQ(r.at("imu_non_monotonic_stamp"), 1U);
  EXPECT_EQ(r.at("mag_non_finite"), 1U);
  EXPECT_EQ(r.at("mag_out_of_range"), 1U);
  EXPECT_EQ(r.at("pressure_non_finite"), 1U);
  EXPECT_EQ(r.at("pressure_out_of_range"), 1U);
  EXPECT_EQ(a.rejected_total(), 10U);
  ASSERT_EQ(out.size(), 2U);
  for (const auto& s : out) {
    EXPECT_TRUE(s.gyro_rps.allFinite() && s.accel_mps2.allFinite() && s.mag_ut.allFinite());
    EXPECT_FALSE(s.has_mag);
    EXPECT_FALSE(s.has_pressure);
  }
}

// Issue 33: one Imu stamped a day ahead became the time base, and every normal Imu after it was
// rejected as non-monotonic for the bridge's lifetime. It is now held as a stamp jump and, when the
// next Imu agrees with the old time base, rejected and counted. Oracle: the stamps sent.
TEST(Ros2Input, GivenOneImuADayAheadThen300NormalOnesThenThe300AreAcceptedAndTheJumpCounted) {
  constexpr int64_t kDayNs = 86'400'000'000'000;
  constexpr int kNormal = 300;
  ImuAssembler a(config(false, false));
  std::vector<ImuSample> out;
  const auto take = [&out](std::vector<ImuSample> v) { out.insert(out.end(), v.begin(), v.end()); };
  take(a.on_imu(imu(kT0)));
  take(a.on_imu(imu(kT0 + kDayNs)));
  for (int k = 1; k <= kNormal; ++k) {
    take(a.on_imu(imu(kT0 + k * kPeriodNs)));
  }
  ASSERT_EQ(out.size(), static_cast<std::size_t>(kNormal + 1));
  for (const ImuSample& sample : out) {
    EXPECT_LT(sample.stamp_ns, kT0 + kDayNs);
  }
  EXPECT_EQ(a.rejected().at("imu_stamp_jump"), 1U);
  EXPECT_EQ(a.rejected_total(), 1U);
}

// A stamp of INT32_MAX s (2038... as ns: the year 2081 after the offset) among normal ones is never
// forwarded, wherever it comes.
TEST(Ros2Input, GivenAnImuStampedInt32MaxSecondsAmongNormalOnesThenItIsNeverForwarded) {
  ImuAssembler a(config(false, false));
  std::vector<ImuSample> out;
  const auto take = [&out](std::vector<ImuSample> v) { out.insert(out.end(), v.begin(), v.end()); };
  for (int k = 0; k < 10; ++k) {
    take(a.on_imu(imu(kT0 + k * kPeriodNs)));
  }
  ros_sensor::Imu_ wild = imu(kT0);
  wild.header().stamp().sec(std::numeric_limits<int32_t>::max());
  take(a.on_imu(wild));
  take(a.on_imu(wild));  // the same wild stamp again does not agree with itself (dt = 0)
  for (int k = 10; k < 20; ++k) {
    take(a.on_imu(imu(kT0 + k * kPeriodNs)));
  }
  ASSERT_EQ(out.size(), 20U);
  EXPECT_EQ(out.back().stamp_ns, kT0 + 19 * kPeriodNs);
  EXPECT_EQ(a.rejected().at("imu_stamp_jump"), 2U);
}

// A clock that really jumped (a driver restarted with another epoch) moves the time base once
// reanchor_samples (3) consecutive Imu agree; the held ones are emitted then, none is lost.
TEST(Ros2Input, GivenAClockThatReallyJumpedThenTheTimeBaseMovesAfterThreeAgreeingSamplesAndNoneIsLost) {
  constexpr int64_t kNewEpoch = 500'000'000'000;  // 500 s
  ImuAssembler a(config(false, false));
  std::vector<ImuSample> out;
  const auto take = [&out](std::vector<ImuSample> v) { out.insert(out.end(), v.begin(), v.end()); };
  for (int k = 0; k < 5; ++k) {
    take(a.on_imu(imu(kT0 + k * kPeriodNs)));
  }
  EXPECT_TRUE(a.on_imu(imu(kNewEpoch)).empty()) << "held: one jumped stamp is not a new clock";
  EXPECT_TRUE(a.on_imu(imu(kNewEpoch + kPeriodNs)).empty());
  take(a.on_imu(imu(kNewEpoch + 2 * kPeriodNs)));  // the third agrees: all three go out
  take(a.on_imu(imu(kNewEpoch + 3 * kPeriodNs)));
  ASSERT_EQ(out.size(), 9U);
  EXPECT_EQ(out[5].stamp_ns, kNewEpoch);
  EXPECT_EQ(out[8].stamp_ns, kNewEpoch + 3 * kPeriodNs);
  EXPECT_EQ(a.rejected_total(), 0U);
}

// Issue 33: one MagneticField stamped in 2038 took the magnetometer pairing from 200/201 to 0/199,
// counted nowhere (its stamp became the stream's newest, so no Imu waited for its magnetometer).
// Oracle: the pairs sent (every Imu has its magnetometer at the same stamp).
TEST(Ros2Input, GivenOneMagneticFieldFarFromTheImuClockThenPairingGoesOnAndItIsCounted) {
  constexpr int kPairs = 200;
  constexpr int64_t k2038Ns = 2'145'916'800'000'000'000;  // 2038-01-01
  ImuAssembler a(config(true, false));
  std::vector<ImuSample> out;
  const auto take = [&out](std::vector<ImuSample> v) { out.insert(out.end(), v.begin(), v.end()); };
  take(a.on_mag(mag(k2038Ns)));  // before any Imu: dropped when the first Imu sets the time base
  for (int k = 0; k < kPairs; ++k) {
    const int64_t t = kT0 + k * kPeriodNs;
    if (k == 0) {  // the first pair magnetometer first: nothing seen yet would not be waited for
      take(a.on_mag(mag(t)));
      take(a.on_imu(imu(t)));
      continue;
    }
    take(a.on_imu(imu(t)));  // Imu first: held until its magnetometer arrives
    take(a.on_mag(mag(t)));
    if (k == kPairs / 2) {
      take(a.on_mag(mag(k2038Ns)));
    }
  }
  take(a.on_imu(imu(kT0 + kPairs * kPeriodNs)));
  EXPECT_EQ(a.paired_mag(), static_cast<uint64_t>(kPairs));
  EXPECT_EQ(a.rejected().at("mag_stamp_jump"), 2U);
  ASSERT_GE(out.size(), static_cast<std::size_t>(kPairs));
  for (int k = 0; k < kPairs; ++k) {
    EXPECT_TRUE(out[static_cast<std::size_t>(k)].has_mag) << k;
  }
}

}  // namespace
}  // namespace poise::ros2
