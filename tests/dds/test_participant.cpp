// Participant setup errors are clear; profiles resolve as documented.
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include "poise/dds/participant.h"
#include "poise/testing/testing.h"

#include <poise/ros2/sensor_msgsPubSubTypes.h>

#include <fastdds/rtps/transport/UDPTransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <gtest/gtest.h>

#include <chrono>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

namespace poise::dds {
namespace {

// Issue 37 (fleet): Fast DDS keeps 10 instances per endpoint by default, and every poise topic is
// keyed by sensor_id, so a reader of the estimates of 20 robots received those of 10 and silently
// dropped the rest. GIVEN 20 instances (sensor_ids) on one keyed topic, written by one writer and
// THEN read by one reader: every instance's samples arrive (oracle: the set of names written).
TEST(Participant, GivenTwentyInstancesOnOneKeyedTopicWhenWrittenAndReadThenEveryInstanceArrives) {
  testing::DomainLease domain;
  constexpr auto kDiscovery = std::chrono::seconds(10);  // bounded wait for discovery
  constexpr int kInstances = 20;                         // twice Fast DDS's default limit
  constexpr int kRounds = 3;
  Participant writer_side({domain.id(), "poise_loopback", "", "fleet_writer"});
  Participant reader_side({domain.id(), "poise_loopback", "", "fleet_reader"});
  std::mutex mutex;
  std::set<std::string> received;
  int samples = 0;
  Reader<msg::AttitudeEstimatePubSubType> reader(
      reader_side, "attitude/parallel_kf", [&](const msg::AttitudeEstimate& m, const auto&) {
        std::lock_guard<std::mutex> lock(mutex);
        received.insert(m.sensor_id().to_string());
        ++samples;
      });
  Writer<msg::AttitudeEstimatePubSubType> writer(writer_side, "attitude/parallel_kf");
  ASSERT_TRUE(writer.wait_for_readers(1, kDiscovery));
  std::set<std::string> written;
  int refused = 0;
  for (int round = 0; round < kRounds; ++round) {
    for (int i = 0; i < kInstances; ++i) {
      msg::AttitudeEstimate m;
      m.sensor_id("robot" + std::to_string(i));
      m.header().seq(static_cast<uint32_t>(round));
      m.q_world_body().w(1.0);
      refused += writer.write(m) ? 0 : 1;
      written.insert(m.sensor_id().to_string());
    }
  }
  EXPECT_EQ(refused, 0) << "the writer refused samples of new instances";
  ASSERT_TRUE(testing::wait_until(
      [&] {
        std::lock_guard<std::mutex> lock(mutex);
        return samples >= kInstances * kRounds;
      },
      kDiscovery));
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_EQ(received, written);
  EXPECT_EQ(samples, kInstances * kRounds);
}

TEST(Participant, UnknownProfileIsAClearError) {
  testing::DomainLease domain;
  ParticipantOptions options;
  options.domain = domain.id();
  options.profile = "no_such_profile";
  try {
    Participant participant(options);
    FAIL() << "expected DdsError";
  } catch (const DdsError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_profile"), std::string::npos) << e.what();
  }
}

TEST(Participant, UnreadableQosFileIsAClearError) {
  EXPECT_THROW(load_profiles("/nonexistent/poise_profiles.xml"), DdsError);
}

TEST(Participant, ExplicitProfileWinsOverEnvironment) {
  ParticipantOptions options;
  options.profile = "poise_udp";
  EXPECT_EQ(resolve_participant_profile(options), "poise_udp");
}

// Issue 37: a UDP send that waits for kernel buffer space blocked the IMU driver's writer 2.65 s.
// Every built-in profile (and the built-in transports of poise_default) sends without waiting;
// poise_default keeps shared memory beside UDPv4, as Fast DDS's built-in transports do.
TEST(Participant, GivenEveryShippedProfileWhenItsQosIsMadeThenEveryUdpTransportSendsWithoutBlocking) {
  namespace rtps = eprosima::fastdds::rtps;
  // (config/qos/discovery_server_client.xml's profiles take the same path: a user UDPv4 transport;
  // loading it here beside the built-in file would only log its duplicate endpoint profiles.)
  for (const std::string profile : {"poise_default", "poise_udp", "poise_loopback"}) {
    SCOPED_TRACE(profile);
    ParticipantOptions o;
    o.profile = profile;
    const auto qos = participant_qos(o);
    EXPECT_FALSE(qos.transport().use_builtin_transports) << "the built-in UDP transport would block";
    int udp = 0;
    int shm = 0;
    for (const auto& d : qos.transport().user_transports) {
      if (const auto* u = dynamic_cast<const rtps::UDPTransportDescriptor*>(d.get())) {
        ++udp;
        EXPECT_TRUE(u->non_blocking_send);
      }
      shm += dynamic_cast<const rtps::SharedMemTransportDescriptor*>(d.get()) != nullptr ? 1 : 0;
    }
    EXPECT_GE(udp, 1);
    EXPECT_EQ(shm, profile == "poise_default" ? 1 : 0);
  }
}

TEST(Participant, TopicNameCannotChangeType) {
  testing::DomainLease domain;
  Participant participant({domain.id(), "", "", "test"});
  Writer<msg::ImuSamplePubSubType> imu(participant, "shared_name");
  EXPECT_THROW((Writer<msg::AltitudeEstimatePubSubType>(participant, "shared_name")), DdsError);
  // Same name and type: the topic is reused.
  EXPECT_NO_THROW((Writer<msg::ImuSamplePubSubType>(participant, "shared_name")));
}

/// Polls `done` every 10 ms until it is true or `timeout` passes.
template <class F>
bool wait_until(F done, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) {
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

// Issue 16: a ROS 2 driver's sensor_msgs/Imu on a topic poise reads as ImuSample is never
// delivered; the reader's process says so once per remote type, naming the topic and both types,
// whether the foreign writer appears after the reader or before it. Oracle: the type names the
// generated type supports register.
TEST(Participant, GivenWritersOfAnotherTypeOnAReadTopicThenOneWarningNamesTopicAndBothTypes) {
  testing::DomainLease domain;
  constexpr auto kDiscovery = std::chrono::seconds(10);  // bounded wait for discovery
  Participant reader_side({domain.id(), "", "", "reader"});
  std::mutex mutex;
  std::vector<std::string> lines;
  reader_side.set_warning_sink([&](const std::string& line) {
    std::lock_guard<std::mutex> lock(mutex);
    lines.push_back(line);
  });
  Reader<msg::ImuSamplePubSubType> reader(reader_side, "imu", [](const auto&, const auto&) {});

  Participant ros_a({domain.id(), "", "", "ros_a"});
  Participant ros_b({domain.id(), "", "", "ros_b"});
  Writer<sensor_msgs::msg::dds_::Imu_PubSubType> foreign_a(ros_a, "imu", QosKind::kSensor);
  Writer<sensor_msgs::msg::dds_::Imu_PubSubType> foreign_b(ros_b, "imu", QosKind::kSensor);
  // Writers created after the foreign ones, on topics the reader side reads with their type:
  // once these match, each participant's earlier writers have been announced (in order).
  Writer<msg::ImuSamplePubSubType> after_a(ros_a, "probe_a");
  Writer<msg::ImuSamplePubSubType> after_b(ros_b, "probe_b");
  Reader<msg::ImuSamplePubSubType> probe_a(reader_side, "probe_a", [](const auto&, const auto&) {});
  Reader<msg::ImuSamplePubSubType> probe_b(reader_side, "probe_b", [](const auto&, const auto&) {});
  ASSERT_TRUE(probe_a.wait_for_writers(1, kDiscovery));
  ASSERT_TRUE(probe_b.wait_for_writers(1, kDiscovery));
  ASSERT_TRUE(wait_until([&] { return !reader_side.type_mismatches().empty(); }, kDiscovery));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // a second warning would be here
  const std::vector<TypeMismatch> seen = reader_side.type_mismatches();
  ASSERT_EQ(seen.size(), 1U);
  EXPECT_EQ(seen[0].topic, "imu");
  EXPECT_EQ(seen[0].local_type, msg::ImuSamplePubSubType().getName());
  EXPECT_EQ(seen[0].remote_type, sensor_msgs::msg::dds_::Imu_PubSubType().getName());
  EXPECT_EQ(reader.matched(), 0);  // DDS matched neither foreign writer
  {
    std::lock_guard<std::mutex> lock(mutex);
    ASSERT_EQ(lines.size(), 1U);
    EXPECT_NE(lines[0].find("'imu'"), std::string::npos) << lines[0];
    EXPECT_NE(lines[0].find("poise::msg::ImuSample"), std::string::npos) << lines[0];
    EXPECT_NE(lines[0].find("sensor_msgs::msg::dds_::Imu_"), std::string::npos) << lines[0];
    EXPECT_NE(lines[0].find("ros2_bridge"), std::string::npos) << lines[0];
  }

  // A writer already known when the reader is created is reported too.
  Writer<msg::VehicleInputPubSubType> early(ros_a, "early", QosKind::kSensor);
  Writer<msg::ImuSamplePubSubType> after_early(ros_a, "probe_c");
  Reader<msg::ImuSamplePubSubType> probe_c(reader_side, "probe_c", [](const auto&, const auto&) {});
  ASSERT_TRUE(probe_c.wait_for_writers(1, kDiscovery));  // `early` is known by now
  Reader<msg::ImuSamplePubSubType> late(reader_side, "early", [](const auto&, const auto&) {});
  ASSERT_TRUE(wait_until([&] { return reader_side.type_mismatches().size() == 2; }, kDiscovery));
  const TypeMismatch second = reader_side.type_mismatches().at(1);
  EXPECT_EQ(second.topic, "early");
  EXPECT_EQ(second.remote_type, msg::VehicleInputPubSubType().getName());
}

}  // namespace
}  // namespace poise::dds
