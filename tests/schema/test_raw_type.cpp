// The raw payload type: verbatim bytes, fastddsgen-identical instance keys, and interop with typed
// endpoints over DDS (typed writer -> raw reader for echo/recording; raw writer -> typed reader for
// replay). Loopback-only participants on an exclusive test domain; every wait bounded.
#include "poise/dds/participant.h"
#include "poise/schema/cdr.h"
#include "poise/schema/observer.h"
#include "poise/schema/raw_type.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <vector>

namespace poise::schema {
namespace {

namespace fdds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;
using std::chrono::milliseconds;

constexpr milliseconds kDiscoveryTimeout{10000};  // bound on every DDS wait
constexpr const char* kLoopback = "poise_loopback";

template <class PubSubType>
std::vector<std::uint8_t> serialize(typename PubSubType::type& msg) {
  PubSubType type;
  rtps::SerializedPayload_t payload(type.m_typeSize);
  EXPECT_TRUE(type.serialize(&msg, &payload));
  return {payload.data, payload.data + payload.length};
}

TEST(RawType, GivenAPayloadWhenSerializedAndDeserializedThenTheBytesAreVerbatim) {
  poise::dds::RawPubSubType type("poise::msg::ImuSample", &TypeTable::builtin());
  EXPECT_EQ(std::string(type.getName()), "poise::msg::ImuSample");
  EXPECT_EQ(type.m_typeSize, poise::msg::ImuSamplePubSubType().m_typeSize);
  poise::msg::ImuSample m;
  m.sensor_id("imu0");
  m.header().seq(9);
  poise::dds::RawSample in{serialize<poise::msg::ImuSamplePubSubType>(m)};
  rtps::SerializedPayload_t payload(type.m_typeSize);
  ASSERT_TRUE(type.serialize(&in, &payload));
  EXPECT_EQ(payload.length, in.data.size());
  EXPECT_EQ(type.getSerializedSizeProvider(&in)(), in.data.size());
  poise::dds::RawSample out;
  ASSERT_TRUE(type.deserialize(&payload, &out));
  EXPECT_EQ(out.data, in.data);

  poise::dds::RawSample too_big{std::vector<std::uint8_t>(type.m_typeSize + 1, 0)};
  EXPECT_FALSE(type.serialize(&too_big, &payload));
  poise::dds::RawSample no_header{{0x00}};
  EXPECT_FALSE(type.serialize(&no_header, &payload));
}

TEST(RawType, GivenKeyedTopicTypesWhenKeysAreComputedThenTheyEqualTheGeneratedTypeSupport) {
  poise::dds::RawPubSubType raw("poise::msg::ImuSample", &TypeTable::builtin());
  ASSERT_TRUE(raw.m_isGetKeyDefined);
  ASSERT_TRUE(raw.computes_keys());
  poise::msg::ImuSamplePubSubType typed;
  for (const char* id : {"", "imu0", "a-very-long-sensor-identifier-0123456789-abcdefghijklmnopqrstu"}) {
    poise::msg::ImuSample m;
    m.sensor_id(id);
    m.header().seq(42);  // not part of the key
    poise::dds::RawSample sample{serialize<poise::msg::ImuSamplePubSubType>(m)};
    rtps::InstanceHandle_t expected;
    rtps::InstanceHandle_t got;
    ASSERT_TRUE(typed.getKey(&m, &expected));
    ASSERT_TRUE(raw.getKey(&sample, &got));
    EXPECT_EQ(got, expected) << "sensor_id '" << id << "'";
    rtps::InstanceHandle_t forced;
    ASSERT_TRUE(raw.getKey(&sample, &forced, true));
    EXPECT_EQ(forced, expected);
  }
  // Untrusted bytes never make getKey() fail (Fast DDS 2.9 aborts on a keyed change it cannot
  // place): every undecodable payload, empty included, goes to the one undecodable instance.
  for (const std::vector<std::uint8_t>& garbage :
       {std::vector<std::uint8_t>{0x00, 0x01, 0x00, 0x00, 0x01}, std::vector<std::uint8_t>{},
        std::vector<std::uint8_t>{0x00, 0x07, 0x00, 0x00}}) {
    poise::dds::RawSample sample{garbage};
    rtps::InstanceHandle_t h;
    ASSERT_TRUE(raw.getKey(&sample, &h)) << garbage.size() << " bytes";
    EXPECT_EQ(h, poise::dds::RawPubSubType::undecodable_instance());
    EXPECT_TRUE(h.isDefined());
  }

  poise::msg::FilterDiagnosticsPubSubType typed_diag;
  poise::dds::RawPubSubType raw_diag("poise::msg::FilterDiagnostics", &TypeTable::builtin());
  poise::msg::FilterDiagnostics d;
  d.sensor_id("kf");
  poise::dds::RawSample ds{serialize<poise::msg::FilterDiagnosticsPubSubType>(d)};
  rtps::InstanceHandle_t de;
  rtps::InstanceHandle_t dg;
  ASSERT_TRUE(typed_diag.getKey(&d, &de));
  ASSERT_TRUE(raw_diag.getKey(&ds, &dg));
  EXPECT_EQ(dg, de);
}

TEST(RawType, GivenAnUnknownTypeWhenCreatedThenItIsKeyedOnlyOnRequestWithOneFixedInstance) {
  poise::dds::RawPubSubType unkeyed("other::Type", &TypeTable::builtin());
  EXPECT_FALSE(unkeyed.m_isGetKeyDefined);
  EXPECT_EQ(unkeyed.m_typeSize, poise::dds::RawPubSubType::kDefaultMaxSize);
  poise::dds::RawPubSubType keyed("other::Type", nullptr, true, 1000);
  EXPECT_TRUE(keyed.m_isGetKeyDefined);
  EXPECT_FALSE(keyed.computes_keys());
  EXPECT_EQ(keyed.m_typeSize, 1000U);
  poise::dds::RawSample any{{0x00, 0x01, 0x00, 0x00}};
  rtps::InstanceHandle_t h;
  ASSERT_TRUE(keyed.getKey(&any, &h));
  EXPECT_EQ(h, poise::dds::RawPubSubType::undecodable_instance());
}

// GIVEN a typed poise writer WHEN the observer discovers it and subscribes with the raw type THEN
// it learns the type and keyed-ness and receives the exact bytes fastcdr serialized.
TEST(RawType, GivenATypedWriterWhenObservedThenTheRawReaderGetsTheExactPayload) {
  poise::testing::DomainLease lease;
  poise::dds::ParticipantOptions popts;
  popts.domain = lease.id();
  popts.profile = kLoopback;
  poise::dds::Participant participant(popts);
  poise::dds::Writer<poise::msg::FilterDiagnosticsPubSubType> writer(participant, "diagnostics");

  ObserverOptions oopts;
  oopts.domain = lease.id();
  oopts.profile = kLoopback;
  TopicObserver observer(oopts);
  const auto found = observer.wait_for_writer("diagnostics", kDiscoveryTimeout);
  ASSERT_TRUE(found.has_value());
  EXPECT_EQ(found->type, "poise::msg::FilterDiagnostics");
  EXPECT_TRUE(found->keyed);
  EXPECT_TRUE(found->reliable);

  std::mutex mutex;
  std::vector<std::vector<std::uint8_t>> got;
  observer.subscribe(*found, &TypeTable::builtin(),
                     [&](const poise::dds::RawSample& s, const fdds::SampleInfo& /*info*/) {
                       std::lock_guard<std::mutex> lock(mutex);
                       got.push_back(s.data);
                     });
  ASSERT_TRUE(writer.wait_for_readers(1, kDiscoveryTimeout));
  ASSERT_TRUE(poise::testing::wait_until(
      [&] { return observer.matched_writers("diagnostics") == 1; }, kDiscoveryTimeout));
  poise::msg::FilterDiagnostics m;
  m.sensor_id("kf0");
  m.component_name("parallel_kf");
  m.header().seq(5);
  ASSERT_TRUE(writer.write(m));
  ASSERT_TRUE(poise::testing::wait_until(
      [&] {
        std::lock_guard<std::mutex> lock(mutex);
        return !got.empty();
      },
      kDiscoveryTimeout));
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_EQ(got.front(), serialize<poise::msg::FilterDiagnosticsPubSubType>(m));
  EXPECT_THROW(observer.subscribe(*found, &TypeTable::builtin(), {}), std::runtime_error);
}

// GIVEN recorded payloads WHEN republished with a raw writer under the original type name THEN a
// typed reader decodes them and sees the same instance (key) as a typed writer would produce.
TEST(RawType, GivenARawWriterWhenATypedReaderSubscribesThenItReceivesTheSampleWithItsKey) {
  poise::testing::DomainLease lease;
  poise::dds::ParticipantOptions popts;
  popts.domain = lease.id();
  popts.profile = kLoopback;
  poise::dds::Participant pub_participant(popts);
  poise::dds::Participant sub_participant(popts);

  fdds::TypeSupport raw(new poise::dds::RawPubSubType("poise::msg::ImuSample", &TypeTable::builtin()));
  fdds::Topic* topic = pub_participant.topic("imu", raw);
  poise::dds::detail::MatchCounter pub_matches;
  fdds::DataWriter* raw_writer = poise::dds::detail::create_writer(
      pub_participant, topic, poise::dds::QosKind::kSensor, &pub_matches);

  std::mutex mutex;
  std::vector<std::pair<poise::msg::ImuSample, rtps::InstanceHandle_t>> got;
  poise::dds::Reader<poise::msg::ImuSamplePubSubType> reader(
      sub_participant, "imu", [&](const poise::msg::ImuSample& s, const fdds::SampleInfo& info) {
        std::lock_guard<std::mutex> lock(mutex);
        got.emplace_back(s, info.instance_handle);
      });
  ASSERT_TRUE(reader.wait_for_writers(1, kDiscoveryTimeout));
  ASSERT_TRUE(poise::dds::detail::wait_matched(pub_matches, 1, kDiscoveryTimeout));

  poise::msg::ImuSample m;
  m.sensor_id("imu7");
  m.header().stamp_ns(123456789);
  m.accel_mps2().z(9.81);
  poise::dds::RawSample sample{serialize<poise::msg::ImuSamplePubSubType>(m)};
  // Best-effort: repeat until one arrives (bounded).
  ASSERT_TRUE(poise::testing::wait_until(
      [&] {
        raw_writer->write(&sample);
        std::lock_guard<std::mutex> lock(mutex);
        return !got.empty();
      },
      kDiscoveryTimeout));
  raw_writer->set_listener(nullptr);
  pub_participant.publisher()->delete_datawriter(raw_writer);

  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_EQ(got.front().first.sensor_id().to_string(), "imu7");
  EXPECT_EQ(got.front().first.header().stamp_ns(), 123456789);
  EXPECT_EQ(got.front().first.accel_mps2().z(), 9.81);
  poise::msg::ImuSamplePubSubType typed;
  rtps::InstanceHandle_t expected;
  ASSERT_TRUE(typed.getKey(&m, &expected));
  EXPECT_EQ(got.front().second, expected);
}

}  // namespace
}  // namespace poise::schema
