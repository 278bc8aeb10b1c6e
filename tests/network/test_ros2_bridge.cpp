// The ros2_bridge component against an independent implementation standing in for ROS 2 (ROS 2 is
// not installed here): Cyclone DDS programs built from the same idl/ros2 (poise_cyclone_ros2).
//  - every bridged output is read as the ROS 2 type and checked field by field against the poise
//    message it came from (units, frames, covariance layout, stamps);
//  - a ROS-2-driver-like Imu + MagneticField stream (MagneticField at half the rate) drives
//    config/hosts/ros2_robot.yaml, and the parallel KF's estimates equal those from the same
//    stream fed natively on poise's `imu` (quaternions within 1e-9).
// Loopback only (poise_loopback profile, Cyclone restricted to lo), leased domains, bounded waits.
#include "netlab.h"
#include "poise/dds/participant.h"
#include "poise/ros2_bridge/bridge.h"
#include "poise/runtime/host.h"

#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/ros2/sensor_msgsPubSubTypes.h>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <set>
#include <thread>

namespace poise::runtime {
void register_estimator_nodes(ComponentRegistry& registry);
}  // namespace poise::runtime

namespace poise::nettest {
namespace {

using namespace std::chrono_literals;

void register_components() {
  auto& registry = runtime::ComponentRegistry::instance();
  if (registry.find("ros2_bridge") == nullptr) {
    ros2::register_ros2_bridge(registry);
  }
  if (registry.find("parallel_kf") == nullptr) {
    runtime::register_estimator_nodes(registry);
  }
}

/// A ros2_bridge component named "ros2", started on its own domain (a lease) and participant
/// with `params` (YAML): the setup every bridge test shares.
struct StartedBridge {
  StartedBridge(const std::string& participant_name, const std::string& params)
      : participant({lease.id(), "", "", participant_name}), context{participant, dds::TopicNames{}} {
    register_components();
    runtime::ComponentSpec spec;
    spec.type = "ros2_bridge";
    spec.name = "ros2";
    spec.origin = "test";
    spec.params = YAML::Load(params);
    bridge = runtime::ComponentRegistry::instance().find("ros2_bridge")->create(spec, context);
    bridge->start();
  }
  testing::DomainLease lease;
  dds::Participant participant;
  runtime::HostContext context;
  std::unique_ptr<runtime::Component> bridge;
};

// --- the poise messages of round k (stamps in sensor mode: header.stamp = stamp_ns) ---
constexpr int64_t kT0 = 1'000'000'000;     // 1 s
constexpr int64_t kPeriod = 20'000'000;    // 20 ms
int64_t stamp_of(int k) { return kT0 + k * kPeriod; }
double angle_of(int k) { return 0.01 * k; }  // rotation about z (up), rad

msg::ImuSample imu_of(int k) {
  msg::ImuSample m;
  m.header().stamp_ns(stamp_of(k));
  m.header().seq(static_cast<uint32_t>(k));
  m.header().frame_id("body");
  m.sensor_id("imu0");
  m.gyro_rps().x(0.1 + 1e-3 * k);
  m.gyro_rps().y(-0.2);
  m.gyro_rps().z(0.3);
  m.accel_mps2().x(0.5);
  m.accel_mps2().y(-0.25);
  m.accel_mps2().z(9.80665 + 1e-3 * k);
  m.mag_ut().x(20.0 + k);
  m.mag_ut().y(-5.0);
  m.mag_ut().z(-40.0);
  m.pressure_pa(101325.0 + k);
  m.valid().accel(true);
  m.valid().gyro(true);
  m.valid().mag(true);
  m.valid().pressure(true);
  return m;
}
msg::Quaternion q_of(int k) {
  msg::Quaternion q;
  q.w(std::cos(angle_of(k) / 2));
  q.z(std::sin(angle_of(k) / 2));
  return q;
}
msg::AttitudeEstimate attitude_of(int k) {
  msg::AttitudeEstimate a;
  a.header().stamp_ns(stamp_of(k));
  a.header().seq(static_cast<uint32_t>(k));
  a.header().frame_id("world");
  a.filter_id("pkf");
  a.q_world_body(q_of(k));
  for (std::size_t i = 0; i < 9; ++i) {
    a.attitude_covariance()[i] = 1e-4 * static_cast<double>(i + 1) + 1e-6 * k;
  }
  return a;
}
double pose_cov(std::size_t r, std::size_t c, int k) { return 100.0 * static_cast<double>(r + 1) + static_cast<double>(c + 1) + k; }
msg::PoseEstimate pose_of(int k) {
  msg::PoseEstimate p;
  p.header().stamp_ns(stamp_of(k));
  p.header().frame_id("world");
  p.filter_id("sekf");
  p.position_m().x(k);
  p.position_m().y(2.0);
  p.position_m().z(3.0);
  p.velocity_mps().x(1.0);
  p.velocity_mps().y(0.25);
  p.velocity_mps().z(0.5);
  p.q_world_body(q_of(k));
  for (std::size_t r = 0; r < 9; ++r) {
    for (std::size_t c = 0; c < 9; ++c) {
      p.covariance()[r * 9 + c] = pose_cov(r, c, k);
    }
  }
  return p;
}
msg::AltitudeEstimate altitude_of(int k) {
  msg::AltitudeEstimate a;
  a.header().stamp_ns(stamp_of(k));
  a.height_m(10.0 + k);
  a.vertical_velocity_mps(-0.5);
  return a;
}

constexpr double kRotTol = 1e-12;  // one rotation of O(1) vectors, rounding only
constexpr int kPerTopic = 10;

TEST(Ros2Bridge, CycloneReadsEveryBridgedOutputAsTheRos2TypeFieldForField) {
  StartedBridge started("ros2_bridge_test",
                        "{namespace: /poise, world_frame: map, body_frame: imu_link, stamps: sensor,"
                        " out: {attitude: [pkf], pose: [sekf], imu: true, altitude: true, tf: attitude/pkf}}");
  testing::DomainLease& lease = started.lease;
  dds::Participant& participant = started.participant;
  auto& bridge = started.bridge;
  dds::Writer<msg::ImuSamplePubSubType> imu(participant, "imu", dds::QosKind::kSensor);
  dds::Writer<msg::AttitudeEstimatePubSubType> att(participant, "attitude/pkf");
  dds::Writer<msg::PoseEstimatePubSubType> pose(participant, "pose/sekf");
  dds::Writer<msg::AltitudeEstimatePubSubType> alt(participant, "altitude");

  const std::string topics =
      "imu:rt/poise/pkf/imu,imu:rt/poise/imu/data_raw,mag:rt/poise/imu/mag,"
      "pressure:rt/poise/imu/pressure,pose:rt/poise/sekf/pose,odom:rt/poise/sekf/odom,"
      "odom:rt/poise/altitude/odom,tf:rt/tf";
  testing::Child reader({testing::bin("poise_cyclone_ros2"), "read", "--domain", std::to_string(lease.id()),
                         "--topics", topics, "--count", std::to_string(kPerTopic), "--timeout-s", "30"},
                        {cyclone_loopback_config()});
  // Publish rounds until the reader has its samples (it matches at its own pace; volatile QoS).
  std::optional<int> rc;
  for (int k = 0; k < 1500 && !rc; ++k) {
    imu.write(imu_of(k));
    att.write(attitude_of(k));
    pose.write(pose_of(k));
    alt.write(altitude_of(k));
    rc = reader.wait_for(20ms);
  }
  if (!rc) {
    rc = reader.wait_for(5s);
  }
  bridge->stop();
  const std::string log = reader.output() + "\nbridge: " + bridge->status();
  ASSERT_EQ(rc, 0) << log;

  std::map<std::string, int> seen;
  for (const Event& s : find_events(reader.output(), "sample")) {
    const std::string topic = s.str("topic");
    const double stamp = s.num("sec") * 1e9 + s.num("nanosec");
    const int k = static_cast<int>(std::lround((stamp - static_cast<double>(kT0)) / static_cast<double>(kPeriod)));
    SCOPED_TRACE(topic + " k=" + std::to_string(k));
    ASSERT_EQ(stamp, static_cast<double>(stamp_of(k))) << "header.stamp = stamp_ns (stamps: sensor)";
    ++seen[topic];
    const msg::ImuSample in = imu_of(k);
    const msg::Quaternion q = q_of(k);
    if (topic == "rt/poise/pkf/imu") {
      EXPECT_EQ(s.str("frame"), "imu_link");
      EXPECT_EQ(s.num("ox"), q.x());
      EXPECT_EQ(s.num("oy"), q.y());
      EXPECT_EQ(s.num("oz"), q.z());
      EXPECT_EQ(s.num("ow"), q.w());
      const auto ocov = split_doubles(s.str("ocov"));
      ASSERT_EQ(ocov.size(), 9U);
      for (std::size_t i = 0; i < 9; ++i) {
        EXPECT_EQ(ocov[i], attitude_of(k).attitude_covariance()[i]) << "rad^2, row-major, world axes";
      }
      EXPECT_EQ(s.num("gx"), in.gyro_rps().x()) << "angular velocity of the sample it came from";
      EXPECT_EQ(s.num("az"), in.accel_mps2().z()) << "specific force of that sample";
      EXPECT_EQ(split_doubles(s.str("gcov")), std::vector<double>(9, 0.0)) << "present, unknown";
      EXPECT_EQ(split_doubles(s.str("acov")), std::vector<double>(9, 0.0));
    } else if (topic == "rt/poise/imu/data_raw") {
      EXPECT_EQ(s.str("frame"), "imu_link");
      EXPECT_EQ(split_doubles(s.str("ocov"))[0], -1.0) << "REP 145: no orientation";
      EXPECT_EQ(s.num("gx"), in.gyro_rps().x());
      EXPECT_EQ(s.num("gy"), in.gyro_rps().y());
      EXPECT_EQ(s.num("gz"), in.gyro_rps().z());
      EXPECT_EQ(s.num("ax"), in.accel_mps2().x());
      EXPECT_EQ(s.num("az"), in.accel_mps2().z());
    } else if (topic == "rt/poise/imu/mag") {
      EXPECT_EQ(s.str("frame"), "imu_link");
      EXPECT_EQ(s.num("mx"), in.mag_ut().x() * 1e-6) << "tesla";
      EXPECT_EQ(s.num("my"), in.mag_ut().y() * 1e-6);
      EXPECT_EQ(s.num("mz"), in.mag_ut().z() * 1e-6);
    } else if (topic == "rt/poise/imu/pressure") {
      EXPECT_EQ(s.num("pressure"), in.pressure_pa()) << "Pa";
      EXPECT_EQ(s.num("variance"), 0.0);
    } else if (topic == "rt/poise/sekf/pose" || topic == "rt/poise/sekf/odom") {
      EXPECT_EQ(s.str("frame"), "map");
      EXPECT_EQ(s.num("px"), static_cast<double>(k));
      EXPECT_EQ(s.num("pz"), 3.0);
      EXPECT_EQ(s.num("qz"), q.z());
      EXPECT_EQ(s.num("qw"), q.w());
      const auto pcov = split_doubles(s.str("pcov"));
      ASSERT_EQ(pcov.size(), 36U);
      const std::size_t from[6] = {0, 1, 2, 6, 7, 8};  // poise [p v theta] rows of ROS [p rot]
      for (std::size_t r = 0; r < 6; ++r) {
        for (std::size_t c = 0; c < 6; ++c) {
          EXPECT_EQ(pcov[r * 6 + c], pose_cov(from[r], from[c], k)) << r << "," << c;
        }
      }
      if (topic == "rt/poise/sekf/odom") {
        EXPECT_EQ(s.str("child"), "imu_link");
        // Twist in the body frame: v_body = R_z(-a) v_world.
        const double a = angle_of(k);
        EXPECT_NEAR(s.num("lx"), std::cos(a) * 1.0 + std::sin(a) * 0.25, kRotTol);
        EXPECT_NEAR(s.num("ly"), -std::sin(a) * 1.0 + std::cos(a) * 0.25, kRotTol);
        EXPECT_NEAR(s.num("lz"), 0.5, kRotTol);
        EXPECT_EQ(s.num("wz"), in.gyro_rps().z()) << "angular rate = the sample's gyro";
        EXPECT_EQ(split_doubles(s.str("tcov"))[3 * 6 + 3], 0.0);
      }
    } else if (topic == "rt/poise/altitude/odom") {
      EXPECT_EQ(s.str("frame"), "map");
      EXPECT_EQ(s.num("pz"), 10.0 + k);
      EXPECT_EQ(s.num("lz"), -0.5);
      const auto pcov = split_doubles(s.str("pcov"));
      EXPECT_EQ(pcov[2 * 6 + 2], 0.0) << "z present";
      EXPECT_EQ(pcov[0], -1.0) << "x absent";
    } else if (topic == "rt/tf") {
      EXPECT_EQ(s.str("frame"), "map");
      EXPECT_EQ(s.str("child"), "imu_link");
      EXPECT_EQ(s.num("count"), 1.0);
      EXPECT_EQ(s.num("rz"), q.z());
      EXPECT_EQ(s.num("rw"), q.w());
      EXPECT_EQ(s.num("tx"), 0.0);
    } else {
      ADD_FAILURE() << "unexpected topic";
    }
  }
  EXPECT_EQ(seen.size(), 8U) << log;
}

// Hostile poise-side input (any participant may publish on attitude/<f>): an estimate holding a
// NaN or a stamp beyond ROS's int32 seconds is never written to ROS 2, it is counted; the good
// ones around it go out. Oracle: what the test sends. A Fast DDS reader of the ROS type watches.
TEST(Ros2Bridge, GivenNonFiniteOrUnstampableEstimatesThenNothingNonFiniteReachesRos2AndEachIsCounted) {
  StartedBridge started("ros2_bridge_hostile", "{stamps: sensor, out: {attitude: [pkf], imu: false, tf: attitude/pkf}}");
  dds::Participant& participant = started.participant;
  auto& bridge = started.bridge;
  std::mutex mutex;
  std::vector<ros2::ros_sensor::Imu_> got;
  dds::Reader<ros2::ros_sensor::Imu_PubSubType> ros(
      participant, "rt/poise/pkf/imu", dds::QosKind::kEstimate, [&](const ros2::ros_sensor::Imu_& m, const auto&) {
        std::lock_guard<std::mutex> lock(mutex);
        got.push_back(m);
      });
  dds::Writer<msg::AttitudeEstimatePubSubType> att(participant, "attitude/pkf");
  constexpr int kGood = 5;
  for (int k = 0; k < kGood; ++k) {
    msg::AttitudeEstimate nan = attitude_of(100 + 2 * k);
    nan.q_world_body().x(std::numeric_limits<double>::quiet_NaN());
    att.write(nan);
    msg::AttitudeEstimate inf = attitude_of(101 + 2 * k);
    inf.attitude_covariance()[4] = std::numeric_limits<double>::infinity();
    att.write(inf);
    msg::AttitudeEstimate far = attitude_of(0);
    far.header().stamp_ns(int64_t{1} << 62);  // 146 years: beyond int32 seconds
    att.write(far);
    att.write(attitude_of(k));
  }
  const auto end = std::chrono::steady_clock::now() + 10s;
  while (std::chrono::steady_clock::now() < end) {
    std::lock_guard<std::mutex> lock(mutex);
    if (got.size() >= static_cast<std::size_t>(kGood)) {
      break;
    }
  }
  std::this_thread::sleep_for(200ms);  // a bad one would arrive with or before the last good one
  // The counters also go out on `diagnostics` (once a second), as every node's do.
  std::map<std::string, uint64_t> diag;
  {
    std::mutex diag_mutex;
    dds::Reader<msg::FilterDiagnosticsPubSubType> diagnostics(
        participant, "diagnostics", [&](const msg::FilterDiagnostics& m, const auto&) {
          std::lock_guard<std::mutex> lock(diag_mutex);
          if (m.component_name() == "ros2_bridge") {
            for (const auto& c : m.counters()) {
              diag[c.name().to_string()] = c.value();
            }
          }
        });
    const auto diag_end = std::chrono::steady_clock::now() + 5s;
    while (std::chrono::steady_clock::now() < diag_end) {
      std::lock_guard<std::mutex> lock(diag_mutex);
      if (diag.count("samples_rejected") != 0) {
        break;
      }
    }
  }
  // Attitude: 10 non-finite + 5 unstampable; tf: 5 NaN quaternions + 5 unstampable (an infinite
  // covariance is not part of a transform, so those 5 transforms go out).
  EXPECT_EQ(diag["samples_rejected"], 25U);
  EXPECT_EQ(diag["attitude_pkf_non_finite"], 10U);
  // Out: attitude 5, its heading status 5 (only with an estimate that went out), tf 5 + 5.
  EXPECT_EQ(diag["ros_messages_out"], 4U * kGood) << "attitude 5, heading status 5, tf 5 + 5";
  const std::string status = bridge->status();
  bridge->stop();
  std::lock_guard<std::mutex> lock(mutex);
  ASSERT_EQ(got.size(), static_cast<std::size_t>(kGood)) << status;
  for (std::size_t k = 0; k < got.size(); ++k) {
    EXPECT_TRUE(ros2::all_finite(got[k]));
    EXPECT_EQ(got[k].orientation().z(), q_of(static_cast<int>(k)).z());
  }
  EXPECT_NE(status.find("attitude_pkf_non_finite=10"), std::string::npos) << status;
  EXPECT_NE(status.find("attitude_pkf_bad_stamp=5"), std::string::npos) << status;
  EXPECT_NE(status.find("tf_non_finite=5"), std::string::npos) << status << " (NaN q; inf covariance is not in tf)";
  EXPECT_NE(status.find("tf_bad_stamp=5"), std::string::npos) << status;
}

/// The parallel KF's estimates by seq: (stamp, q).
struct Estimates {
  std::mutex mutex;
  std::map<uint32_t, msg::AttitudeEstimate> by_seq;
  std::size_t size() {
    std::lock_guard<std::mutex> lock(mutex);
    return by_seq.size();
  }
};

bool wait_for_count(Estimates& e, std::size_t n, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (e.size() < n) {
    if (std::chrono::steady_clock::now() > end) {
      return false;
    }
    std::this_thread::sleep_for(10ms);
  }
  return true;
}

TEST(Ros2Bridge, RosDriverImuAndMagStreamGiveTheParallelKfTheSameEstimatesAsTheNativeStream) {
  register_components();
  testing::DomainLease lease;
  constexpr int kSamples = 400;    // 2 s at 200 Hz
  constexpr double kQuatTol = 1e-9;
  // GIVEN the ROS 2 robot host file (ROS IMU in, poise estimates out) ...
  const runtime::HostSpec robot = runtime::load_host_file(testing::source_path("config/hosts/ros2_robot.yaml"));
  runtime::Host host(robot, lease.id());
  // ... and the same filter on a native poise stream (its own topic names, same domain)
  runtime::HostSpec native_spec;
  native_spec.topics.imu = "native/imu";
  native_spec.topics.attitude_prefix = "native/attitude/";
  native_spec.topics.diagnostics = "native/diagnostics";
  runtime::ComponentSpec kf;
  kf.type = "parallel_kf";
  kf.name = "parallel_kf";
  kf.origin = "test";
  native_spec.components.push_back(kf);
  runtime::Host native(native_spec, lease.id());
  dds::Participant participant({lease.id(), "", "", "ros2_robot_test"});
  Estimates bridged;
  Estimates direct;
  const auto collect = [](Estimates& into) {
    return [&into](const msg::AttitudeEstimate& m, const auto&) {
      std::lock_guard<std::mutex> lock(into.mutex);
      into.by_seq[m.header().seq()] = m;
    };
  };
  dds::Reader<msg::AttitudeEstimatePubSubType> from_ros(participant, "attitude/parallel_kf", collect(bridged));
  dds::Reader<msg::AttitudeEstimatePubSubType> from_native(participant, "native/attitude/parallel_kf",
                                                           collect(direct));
  host.start();
  native.start();

  // WHEN a ROS 2 driver (Cyclone DDS) publishes Imu at 200 Hz and MagneticField at 100 Hz
  testing::Child driver({testing::bin("poise_cyclone_ros2"), "publish", "--domain", std::to_string(lease.id()),
                         "--imu-topic", "rt/imu/data", "--mag-topic", "rt/imu/mag", "--count",
                         std::to_string(kSamples), "--rate-hz", "200", "--mag-every", "2", "--timeout-s", "20"},
                        {cyclone_loopback_config()});
  ASSERT_EQ(driver.wait_for(40s), 0) << driver.output() << "\n" << host.status().front();
  // The last Imu waits for a magnetometer sample at or after its stamp (the MagneticField stream
  // runs at half the rate) or the next Imu: neither comes, so it stays held (docs/ROS2.md).
  constexpr std::size_t kBridged = kSamples - 1;
  const bool all_bridged = wait_for_count(bridged, kBridged, 10s);
  // AND the same samples go natively (the magnetometer in microtesla, as a poise driver sends it)
  dds::Writer<msg::ImuSamplePubSubType> native_imu(participant, "native/imu", dds::QosKind::kSensor);
  const auto sent = find_events(driver.output(), "sent");
  ASSERT_EQ(sent.size(), static_cast<std::size_t>(kSamples));
  ASSERT_TRUE(native_imu.wait_for_readers(1, 10s));
  for (const Event& e : sent) {
    msg::ImuSample m;
    m.header().stamp_ns(static_cast<int64_t>(e.num("sec")) * 1'000'000'000LL + static_cast<int64_t>(e.num("nanosec")));
    m.header().seq(static_cast<uint32_t>(e.num("k")));
    m.header().frame_id("body");
    m.sensor_id("native");
    m.gyro_rps().x(e.num("gx"));
    m.gyro_rps().y(e.num("gy"));
    m.gyro_rps().z(e.num("gz"));
    m.accel_mps2().x(e.num("ax"));
    m.accel_mps2().y(e.num("ay"));
    m.accel_mps2().z(e.num("az"));
    m.mag_ut().x(e.num("mx_ut"));
    m.mag_ut().y(e.num("my_ut"));
    m.mag_ut().z(e.num("mz_ut"));
    m.valid().accel(true);
    m.valid().gyro(true);
    m.valid().mag(e.num("mag") == 1.0);
    native_imu.write(m);
    std::this_thread::sleep_for(1ms);
  }
  ASSERT_TRUE(wait_for_count(direct, kSamples, 10s)) << direct.size();
  const std::string status = host.status().front() + " | " + host.status().back();
  host.stop();
  native.stop();
  ASSERT_TRUE(all_bridged) << "bridged estimates: " << bridged.size() << "\n" << status;

  // THEN every estimate agrees, seq by seq (same stamps up to the ROS clock offset)
  std::lock_guard<std::mutex> l1(bridged.mutex);
  std::lock_guard<std::mutex> l2(direct.mutex);
  ASSERT_EQ(bridged.by_seq.size(), kBridged);
  ASSERT_EQ(direct.by_seq.size(), static_cast<std::size_t>(kSamples));
  double worst = 0.0;
  int64_t offset = 0;
  for (const auto& [seq, b] : bridged.by_seq) {
    const auto it = direct.by_seq.find(seq);
    ASSERT_NE(it, direct.by_seq.end()) << seq;
    const msg::AttitudeEstimate& d = it->second;
    const int64_t dt = d.header().stamp_ns() - b.header().stamp_ns();
    if (seq == bridged.by_seq.begin()->first) {
      offset = dt;
    }
    EXPECT_EQ(dt, offset) << "one constant clock offset (CLOCK_REALTIME - CLOCK_MONOTONIC)";
    const auto& qb = b.q_world_body();
    const auto& qd = d.q_world_body();
    const double sign = qb.w() * qd.w() + qb.x() * qd.x() + qb.y() * qd.y() + qb.z() * qd.z() < 0 ? -1.0 : 1.0;
    for (double diff : {qb.w() - sign * qd.w(), qb.x() - sign * qd.x(), qb.y() - sign * qd.y(),
                        qb.z() - sign * qd.z()}) {
      worst = std::max(worst, std::abs(diff));
    }
  }
  std::printf("ros2_robot vs native: %zu estimates, largest quaternion component difference %.3g\n",
              bridged.by_seq.size(), worst);
  EXPECT_LE(worst, kQuatTol);
  EXPECT_NE(status.find("mag paired 200"), std::string::npos) << status;
}

}  // namespace
}  // namespace poise::nettest
