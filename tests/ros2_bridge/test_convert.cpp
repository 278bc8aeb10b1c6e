// The bridge's conversions (components/bridges/ros2_bridge/convert.h): field order, units, frames,
// REP 145 covariance conventions, the 9x9 -> 6x6 covariance re-layout and the stamp mapping, each
// against an oracle written here by hand.
#include "poise/ros2_bridge/convert.h"

#include <poise/ros2/sensor_msgsPubSubTypes.h>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace poise::ros2 {
namespace {

const Frames kFrames{"map", "imu_link"};
constexpr double kExact = 0.0;     // copied doubles: bit-identical
constexpr double kRotTol = 1e-15;  // one rotation of unit vectors, rounding only

/// A 9x9 entry that names its own row and column: 100 * (row + 1) + column + 1.
double entry(std::size_t r, std::size_t c) { return 100.0 * static_cast<double>(r + 1) + static_cast<double>(c + 1); }

TEST(Ros2Convert, GivenStampsThenRosTimeSplitsWithFloorAndOffsetAndRefusesOverflow) {
  const auto t = to_ros_time(1'500'000'123LL, 1'700'000'000'000'000'000LL);
  ASSERT_TRUE(t.has_value());
  EXPECT_EQ(t->sec(), 1'700'000'001);
  EXPECT_EQ(t->nanosec(), 500'000'123U);
  const auto negative = to_ros_time(-1, 0);  // floor: -1 ns = -1 s + 999999999 ns
  ASSERT_TRUE(negative.has_value());
  EXPECT_EQ(negative->sec(), -1);
  EXPECT_EQ(negative->nanosec(), 999'999'999U);
  EXPECT_FALSE(to_ros_time(int64_t{1} << 62, 0).has_value()) << "beyond int32 seconds";
  EXPECT_FALSE(to_ros_time(std::numeric_limits<int64_t>::max(), 1).has_value()) << "sum overflows";
  // And back.
  EXPECT_EQ(from_ros_time(*t, 1'700'000'000'000'000'000LL), 1'500'000'123LL);
  ros_time::Time_ bad;
  bad.sec(1);
  bad.nanosec(1'000'000'000U);
  EXPECT_FALSE(from_ros_time(bad, 0).has_value()) << "nanosec must be < 1e9";
  bad.sec(-1);
  bad.nanosec(0);
  EXPECT_FALSE(from_ros_time(bad, 0).has_value()) << "negative seconds";
}

msg::ImuSample sample() {
  msg::ImuSample in;
  in.header().stamp_ns(2'000'000'007LL);
  in.header().frame_id("body");
  in.gyro_rps().x(0.1);
  in.gyro_rps().y(-0.2);
  in.gyro_rps().z(0.3);
  in.accel_mps2().x(0.5);
  in.accel_mps2().y(-0.25);
  in.accel_mps2().z(9.80665);
  in.mag_ut().x(20.0);
  in.mag_ut().y(-5.0);
  in.mag_ut().z(-40.0);
  in.pressure_pa(101325.0);
  in.valid().gyro(true);
  in.valid().accel(true);
  in.valid().mag(true);
  in.valid().pressure(true);
  return in;
}

TEST(Ros2Convert, GivenAnAttitudeAndItsSampleThenImuCarriesOrientationCovarianceRatesAndForce) {
  msg::AttitudeEstimate a;
  a.header().stamp_ns(2'000'000'007LL);
  a.q_world_body().w(0.5);
  a.q_world_body().x(0.5);
  a.q_world_body().y(-0.5);
  a.q_world_body().z(0.5);
  for (std::size_t k = 0; k < 9; ++k) {
    a.attitude_covariance()[k] = 1e-4 * static_cast<double>(k + 1);
  }
  const msg::ImuSample s = sample();
  const auto out = attitude_to_imu(a, &s, kFrames, 0);
  EXPECT_EQ(out.header().frame_id(), "imu_link");
  EXPECT_EQ(out.header().stamp().sec(), 2);
  EXPECT_EQ(out.header().stamp().nanosec(), 7U);
  EXPECT_EQ(out.orientation().x(), 0.5);
  EXPECT_EQ(out.orientation().y(), -0.5);
  EXPECT_EQ(out.orientation().z(), 0.5);
  EXPECT_EQ(out.orientation().w(), 0.5) << "ROS order x, y, z, w";
  for (std::size_t k = 0; k < 9; ++k) {
    EXPECT_NEAR(out.orientation_covariance()[k], 1e-4 * static_cast<double>(k + 1), kExact)
        << "rad^2 about the world axes, row-major, as poise's";
  }
  EXPECT_EQ(out.angular_velocity().y(), -0.2);
  EXPECT_EQ(out.linear_acceleration().z(), 9.80665) << "specific force, +g up at rest (ROS too)";
  EXPECT_EQ(out.angular_velocity_covariance(), (std::array<double, 9>{})) << "present, unknown";
  EXPECT_EQ(out.linear_acceleration_covariance(), (std::array<double, 9>{}));
  // Without its sample: rates and force absent (REP 145: element 0 = -1), values 0.
  const auto alone = attitude_to_imu(a, nullptr, kFrames, 0);
  EXPECT_EQ(alone.angular_velocity_covariance()[0], -1.0);
  EXPECT_EQ(alone.linear_acceleration_covariance()[0], -1.0);
  EXPECT_EQ(alone.angular_velocity().x(), 0.0);
  EXPECT_TRUE(all_finite(alone));
}

TEST(Ros2Convert, GivenARawSampleThenImuMagneticFieldInTeslaAndPressureInPascal) {
  msg::ImuSample s = sample();
  s.valid().accel(false);
  const auto imu = sample_to_imu(s, kFrames, 0);
  EXPECT_EQ(imu.orientation_covariance()[0], -1.0) << "REP 145: no orientation";
  EXPECT_EQ(imu.orientation().w(), 1.0);
  EXPECT_EQ(imu.angular_velocity().x(), 0.1);
  EXPECT_EQ(imu.angular_velocity_covariance()[0], 0.0) << "valid, covariance unknown";
  EXPECT_EQ(imu.linear_acceleration_covariance()[0], -1.0) << "accel flagged invalid";
  const auto mag = sample_to_mag(s, kFrames, 0);
  ASSERT_TRUE(mag.has_value());
  EXPECT_EQ(mag->header().frame_id(), "imu_link");
  EXPECT_DOUBLE_EQ(mag->magnetic_field().x(), 20e-6) << "tesla";
  EXPECT_DOUBLE_EQ(mag->magnetic_field().y(), -5e-6);
  EXPECT_DOUBLE_EQ(mag->magnetic_field().z(), -40e-6);
  const auto p = sample_to_pressure(s, kFrames, 0);
  ASSERT_TRUE(p.has_value());
  EXPECT_EQ(p->fluid_pressure(), 101325.0);
  EXPECT_EQ(p->variance(), 0.0);
  s.valid().mag(false);
  s.valid().pressure(false);
  EXPECT_FALSE(sample_to_mag(s, kFrames, 0).has_value());
  EXPECT_FALSE(sample_to_pressure(s, kFrames, 0).has_value());
}

msg::PoseEstimate pose_estimate() {
  msg::PoseEstimate in;
  in.header().stamp_ns(5);
  in.position_m().x(1.0);
  in.position_m().y(2.0);
  in.position_m().z(3.0);
  // 90 deg about z (ENU up): body x points north.
  in.q_world_body().w(std::sqrt(0.5));
  in.q_world_body().z(std::sqrt(0.5));
  in.velocity_mps().x(1.0);  // east
  in.velocity_mps().y(0.0);
  in.velocity_mps().z(0.5);
  for (std::size_t r = 0; r < 9; ++r) {
    for (std::size_t c = 0; c < 9; ++c) {
      in.covariance()[r * 9 + c] = entry(r, c);
    }
  }
  return in;
}

TEST(Ros2Convert, GivenAPoseThenPositionQuaternionAndThePositionAndAttitudeCovarianceBlocks) {
  const auto out = pose_to_ros(pose_estimate(), kFrames, 0);
  EXPECT_EQ(out.header().frame_id(), "map");
  EXPECT_EQ(out.pose().pose().position().y(), 2.0);
  EXPECT_EQ(out.pose().pose().orientation().w(), std::sqrt(0.5));
  EXPECT_EQ(out.pose().pose().orientation().z(), std::sqrt(0.5));
  const auto& cov = out.pose().covariance();
  // ROS rows/cols (x y z rx ry rz) = poise rows/cols (0 1 2 6 7 8): velocities left out.
  const std::size_t poise_index[6] = {0, 1, 2, 6, 7, 8};
  for (std::size_t r = 0; r < 6; ++r) {
    for (std::size_t c = 0; c < 6; ++c) {
      EXPECT_EQ(cov[r * 6 + c], entry(poise_index[r], poise_index[c])) << r << "," << c;
    }
  }
}

TEST(Ros2Convert, GivenAPoseThenOdometryTwistIsInTheBodyFrameWithTheGyroAsAngularRate) {
  const msg::PoseEstimate in = pose_estimate();
  const msg::ImuSample s = sample();
  const auto out = pose_to_odometry(in, &s, kFrames, 0);
  EXPECT_EQ(out.header().frame_id(), "map");
  EXPECT_EQ(out.child_frame_id(), "imu_link");
  // Body x = north, body y = west, body z = up: east velocity 1 is body -y; up 0.5 is body z.
  EXPECT_NEAR(out.twist().twist().linear().x(), 0.0, kRotTol);
  EXPECT_NEAR(out.twist().twist().linear().y(), -1.0, kRotTol);
  EXPECT_NEAR(out.twist().twist().linear().z(), 0.5, kRotTol);
  EXPECT_EQ(out.twist().twist().angular().z(), 0.3);
  // Covariance R^T C R with R = [[0,-1,0],[1,0,0],[0,0,1]]: C_body(0,0) = C_world(1,1) (north).
  const auto& tc = out.twist().covariance();
  EXPECT_NEAR(tc[0 * 6 + 0], entry(4, 4), 1e-12);
  EXPECT_NEAR(tc[1 * 6 + 1], entry(3, 3), 1e-12);
  EXPECT_NEAR(tc[2 * 6 + 2], entry(5, 5), 1e-12);
  EXPECT_NEAR(tc[0 * 6 + 1], -entry(4, 3), 1e-12);
  EXPECT_EQ(tc[3 * 6 + 3], 0.0) << "angular rate present, covariance unknown";
  const auto alone = pose_to_odometry(in, nullptr, kFrames, 0);
  EXPECT_EQ(alone.twist().covariance()[3 * 6 + 3], -1.0) << "angular rate absent";
  EXPECT_EQ(alone.pose().covariance(), out.pose().covariance());
}

TEST(Ros2Convert, GivenAnAltitudeThenOdometryZAndVerticalVelocityWithTheRestAbsent) {
  msg::AltitudeEstimate in;
  in.header().stamp_ns(9);
  in.height_m(12.5);
  in.vertical_velocity_mps(-0.75);
  const auto out = altitude_to_odometry(in, kFrames, 0);
  EXPECT_EQ(out.header().frame_id(), "map");
  EXPECT_EQ(out.pose().pose().position().z(), 12.5);
  EXPECT_EQ(out.twist().twist().linear().z(), -0.75);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(out.pose().covariance()[i * 6 + i], i == 2 ? 0.0 : -1.0) << i;
    EXPECT_EQ(out.twist().covariance()[i * 6 + i], i == 2 ? 0.0 : -1.0) << i;
  }
}

TEST(Ros2Convert, GivenAnEstimateThenTfIsWorldToBodyAndNonFiniteMessagesAreDetected) {
  msg::Quaternion q;
  q.w(0.0);
  q.x(1.0);
  msg::Vector3 p;
  p.z(2.0);
  const auto tf = to_tf(1'000'000'000LL, q, p, kFrames, 0);
  ASSERT_EQ(tf.transforms().size(), 1U);
  const auto& t = tf.transforms()[0];
  EXPECT_EQ(t.header().frame_id(), "map");
  EXPECT_EQ(t.child_frame_id(), "imu_link");
  EXPECT_EQ(t.header().stamp().sec(), 1);
  EXPECT_EQ(t.transform().rotation().x(), 1.0);
  EXPECT_EQ(t.transform().translation().z(), 2.0);
  EXPECT_TRUE(all_finite(tf));
  q.w(std::numeric_limits<double>::quiet_NaN());
  EXPECT_FALSE(all_finite(to_tf(0, q, p, kFrames, 0)));
  msg::PoseEstimate bad = pose_estimate();
  bad.covariance()[80] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(all_finite(pose_to_ros(bad, kFrames, 0)));
}

TEST(Ros2Convert, GivenRosNamesThenDdsTopicsHaveTheRtPrefixAndBadNamesAreRefused) {
  EXPECT_EQ(dds_topic("/poise/parallel_kf/imu"), "rt/poise/parallel_kf/imu");
  EXPECT_EQ(dds_topic("imu/data"), "rt/imu/data");
  EXPECT_EQ(dds_topic("/tf"), "rt/tf");
  for (const char* bad : {"", "/", "/a//b", "/a/", "/a b", "/1imu", "/imu/9x", "/a-b"}) {
    EXPECT_THROW(dds_topic(bad), std::invalid_argument) << bad;
  }
}


namespace cdr_reader {

/// A little-endian XCDR1 reader written here from the CDR rules (alignment of each primitive to
/// its size, counted from the end of the 4-byte encapsulation header), independent of the bridge's
/// generated serializer.
class Reader {
 public:
  explicit Reader(const std::vector<uint8_t>& bytes) : b_(bytes) {
    if (b_.size() < 4 || b_[0] != 0x00 || b_[1] != 0x01) {
      throw std::runtime_error("not a little-endian plain CDR payload");
    }
  }
  template <typename T>
  T read() {
    pos_ = (pos_ + sizeof(T) - 1) / sizeof(T) * sizeof(T);
    if (4 + pos_ + sizeof(T) > b_.size()) {
      throw std::runtime_error("payload too short");
    }
    T v;
    std::memcpy(&v, b_.data() + 4 + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::string string() {
    const auto n = read<uint32_t>();  // length including the terminating NUL
    if (n == 0 || 4 + pos_ + n > b_.size()) {
      throw std::runtime_error("bad string length");
    }
    std::string s(reinterpret_cast<const char*>(b_.data() + 4 + pos_), n - 1);
    pos_ += n;
    return s;
  }

 private:
  const std::vector<uint8_t>& b_;
  std::size_t pos_ = 0;
};

}  // namespace cdr_reader

// sensor_msgs/Imu: header {stamp {int32 sec, uint32 nanosec}, string frame_id}, orientation
// {x, y, z, w}, orientation_covariance[9], ... (the public .msg order).
TEST(Ros2Convert, GivenAnAttitudeEstimateWhenBridgedThenAnIndependentCdrDecodeOfTheImuGivesThePublishedCovarianceRowMajor) {
  // A published covariance with distinct variances about world east (x), north (y) and up (z)
  // and distinct correlations, on an attitude yawed 90 deg: if the bridge rotated it into the body
  // frame, or transposed or reordered it, x and y or the off-diagonal entries would trade places.
  Eigen::Matrix3d published;
  published << 1.0e-4, 2.0e-5, -3.0e-5,  //
      2.0e-5, 4.0e-4, 5.0e-5,            //
      -3.0e-5, 5.0e-5, 9.0e-4;
  msg::AttitudeEstimate a;
  a.header().stamp_ns(3'000'000'000LL);
  const double h = std::sqrt(0.5);
  a.q_world_body().w(h);
  a.q_world_body().z(h);  // 90 deg about up
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      a.attitude_covariance()[static_cast<std::size_t>(3 * r + c)] = published(r, c);
    }
  }
  ros_sensor::Imu_ imu = attitude_to_imu(a, nullptr, kFrames, 0);
  ros_sensor::Imu_PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.m_typeSize);
  ASSERT_TRUE(type.serialize(&imu, &payload));
  const std::vector<uint8_t> bytes(payload.data, payload.data + payload.length);

  cdr_reader::Reader in(bytes);
  EXPECT_EQ(in.read<int32_t>(), 3);
  EXPECT_EQ(in.read<uint32_t>(), 0U);
  EXPECT_EQ(in.string(), "imu_link");
  const double qx = in.read<double>();
  const double qy = in.read<double>();
  const double qz = in.read<double>();
  const double qw = in.read<double>();
  EXPECT_EQ(qx, 0.0);
  EXPECT_EQ(qy, 0.0);
  EXPECT_EQ(qz, h);
  EXPECT_EQ(qw, h) << "ROS order x, y, z, w";
  double cov[9];
  for (double& v : cov) {
    v = in.read<double>();
  }
  // REP 145 / sensor_msgs/Imu: row-major, rows and columns the rotation about the fixed frame's
  // x, y, z axes (REP 103: ENU world, east, north, up), rad^2
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(cov[3 * r + c], published(r, c)) << "row " << r << " column " << c;
    }
  }
  EXPECT_EQ(cov[8], 9.0e-4) << "element 8: the yaw variance (rotation about up)";
}

TEST(Ros2Convert, GivenAnUnverifiedHeadingThenTheCompanionStatusIsWarnStampedAsTheImuWithTheYawSigma) {
  msg::AttitudeEstimate a;
  a.header().stamp_ns(2'000'000'007LL);
  a.sensor_id("imu0");
  a.attitude_covariance()[8] = std::pow(10.0 * 3.14159265358979323846 / 180.0, 2);  // (10 deg)^2
  a.heading_status(msg::HEADING_UNVERIFIED);
  const auto d = heading_status_to_diagnostics(a, "parallel_kf", kFrames, 0);
  const auto imu = attitude_to_imu(a, nullptr, kFrames, 0);
  EXPECT_EQ(d.header().stamp().sec(), imu.header().stamp().sec());
  EXPECT_EQ(d.header().stamp().nanosec(), imu.header().stamp().nanosec());
  ASSERT_EQ(d.status().size(), 1U);
  const auto& s = d.status()[0];
  EXPECT_EQ(s.level(), 1) << "WARN";
  EXPECT_EQ(s.name(), "poise/parallel_kf/heading");
  EXPECT_EQ(s.message(), "unverified");
  EXPECT_EQ(s.hardware_id(), "imu0");
  ASSERT_EQ(s.values().size(), 2U);
  EXPECT_EQ(s.values()[0].key(), "heading_status");
  EXPECT_EQ(s.values()[0].value(), "unverified");
  EXPECT_EQ(s.values()[1].key(), "yaw_sigma_deg");
  constexpr double kPrintedDegTol = 1e-4;  // default stream precision (6 digits), deg
  EXPECT_NEAR(std::stod(s.values()[1].value()), 10.0, kPrintedDegTol);
  a.heading_status(msg::HEADING_VERIFIED);
  EXPECT_EQ(heading_status_to_diagnostics(a, "parallel_kf", kFrames, 0).status()[0].level(), 0) << "OK";
  a.heading_status(msg::HEADING_NO_REFERENCE);
  EXPECT_EQ(heading_status_to_diagnostics(a, "parallel_kf", kFrames, 0).status()[0].message(), "no_reference");
}

}  // namespace
}  // namespace poise::ros2
