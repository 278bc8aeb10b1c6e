// Record and replay over DDS on a leased domain (loopback profile), with bounded waits:
//  - payloads are recorded verbatim (byte-equal to what the publisher serialised), publish time =
//    Header.stamp_ns, QoS in the channel metadata; the file passes the independent validator;
//  - replay republishes the same bytes;
//  - after kill -9 the recorder's file holds every message older than the chunk age limit;
//  - the CLI reports write failures (disk full) and damaged files clearly.
#include "poise/dds/participant.h"
#include "poise/record/mcap.h"
#include "poise/record/recorder.h"
#include "recorder_thread.h"
#include "poise/record/replayer.h"
#include "record_test_support.h"

#include <poise/ros2/sensor_msgsPubSubTypes.h>

#include <gtest/gtest.h>

#include <csignal>
#include <map>
#include <mutex>
#include <regex>
#include <sstream>
#include <thread>

namespace poise::record {
namespace {

using namespace std::chrono_literals;
constexpr auto kMatchTimeout = 15s;     // discovery on loopback, generous for loaded CI machines
constexpr auto kDeliveryTimeout = 10s;
constexpr const char* kProfile = "poise_loopback";
// Best-effort delivery we require on loopback: a loaded 2-core CI machine drops some samples;
// what this test checks is that every delivered sample is byte-identical.
constexpr double kMinBestEffortFraction = 0.5;

std::string tool() { return std::string(POISE_RECORD_TOOL); }

template <class PubSubType, class Message>
Message deserialize(const uint8_t* data, size_t size) {
  PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<uint32_t>(size));
  std::memcpy(payload.data, data, size);
  payload.length = static_cast<uint32_t>(size);
  Message m;
  type.deserialize(&payload, &m);
  return m;
}

// The raw payload type and the stamp reader are schema's (tests/schema); here the file names.
TEST(Recorder, SplitFileNamesAreNumbered) {
  EXPECT_EQ(split_file_name("out.mcap", 2), "out_002.mcap");
  EXPECT_EQ(split_file_name("dir/x", 0), "dir/x_000.mcap");
}

/// Collects serialized copies of every sample a typed reader receives.
template <class PubSubType>
struct Collector {
  std::mutex mutex;
  std::map<uint32_t, std::vector<uint8_t>> by_seq;
  void add(const typename PubSubType::type& m) {
    auto bytes = testing::serialize<PubSubType>(m);
    std::lock_guard<std::mutex> lock(mutex);
    by_seq[m.header().seq()] = std::move(bytes);
  }
  size_t size() {
    std::lock_guard<std::mutex> lock(mutex);
    return by_seq.size();
  }
};

TEST(RecordReplay, RecordsPayloadsVerbatimAndReplaysThemByteForByte) {
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("dds");
  ASSERT_FALSE(dir.empty());
  const std::string file = dir + "/recorded.mcap";
  constexpr int kImu = 300;
  constexpr int kAttitudeEvery = 10;
  constexpr int kAttitude = kImu / kAttitudeEvery;
  const int64_t t0 = 1'700'000'000'000'000'000LL;

  // GIVEN a recorder on "imu" and "attitude/parallel_kf"
  RecorderOptions ro = testing::recorder_options(file, lease.id(), kProfile);
  ro.topics = {"imu", "attitude/parallel_kf"};
  ro.writer.max_chunk_duration_ns = 200'000'000;
  testing::RecorderThread recorder(ro);
  std::map<uint32_t, std::vector<uint8_t>> imu_sent;
  std::map<uint32_t, std::vector<uint8_t>> att_sent;
  {
    dds::Participant pub({lease.id(), kProfile, "", "test_pub"});
    dds::Writer<msg::ImuSamplePubSubType> imu(pub, "imu");
    dds::Writer<msg::AttitudeEstimatePubSubType> att(pub, "attitude/parallel_kf");
    const bool matched = poise::testing::wait_until(
        [&] { return recorder->subscribed() == 2 && imu.matched() > 0 && att.matched() > 0; },
        kMatchTimeout);
    ASSERT_TRUE(recorder.matched(matched, "recorder did not subscribe/match within the timeout"));
    // WHEN 300 IMU samples (1 kHz) and 30 attitude estimates are published
    for (int i = 0; i < kImu; ++i) {
      const int64_t stamp = t0 + i * 1'000'000LL;
      const auto m = testing::make_imu(static_cast<uint32_t>(i), stamp);
      imu_sent[m.header().seq()] = testing::serialize<msg::ImuSamplePubSubType>(m);
      imu.write(m);
      if (i % kAttitudeEvery == 0) {
        const auto a = testing::make_attitude(static_cast<uint32_t>(i / kAttitudeEvery), stamp);
        att_sent[a.header().seq()] = testing::serialize<msg::AttitudeEstimatePubSubType>(a);
        att.write(a);
      }
      std::this_thread::sleep_for(1ms);
    }
    poise::testing::wait_until([&] { return recorder->written() >= kImu + kAttitude; },
                               kDeliveryTimeout);
  }
  const RecorderStats rstats = recorder.stop();
  ASSERT_TRUE(rstats.error.empty()) << rstats.error;

  // THEN the file is complete, reliable messages are all there, and every payload is verbatim
  McapReader reader = McapReader::open_file(file);
  ASSERT_TRUE(reader.report().complete);
  reader.verify();
  ASSERT_TRUE(reader.report().complete);
  std::map<std::string, const Channel*> by_topic;
  for (const auto& [id, c] : reader.channels()) {
    by_topic[c.topic] = &c;
  }
  ASSERT_EQ(by_topic.size(), 2u);
  EXPECT_EQ(by_topic["imu"]->metadata.at("reliability"), "BEST_EFFORT");
  EXPECT_EQ(by_topic["attitude/parallel_kf"]->metadata.at("reliability"), "RELIABLE");
  EXPECT_EQ(by_topic["imu"]->message_encoding, "cdr");
  EXPECT_EQ(reader.schemas().at(by_topic["imu"]->schema_id).name, "poise::msg::ImuSample");
  EXPECT_EQ(reader.schemas().at(by_topic["imu"]->schema_id).encoding, "omgidl");
  std::map<uint32_t, std::vector<uint8_t>> imu_rec;
  std::map<uint32_t, std::vector<uint8_t>> att_rec;
  std::vector<testing::ExpectedValue> expected;
  uint64_t last_log = 0;
  MessageCursor cursor = reader.messages();
  while (const MessageView* m = cursor.next()) {
    EXPECT_GE(m->log_time_ns, last_log);
    last_log = m->log_time_ns;
    std::vector<uint8_t> bytes(m->data, m->data + m->size);
    if (m->channel->topic == "imu") {
      const auto msg = deserialize<msg::ImuSamplePubSubType, msg::ImuSample>(m->data, m->size);
      EXPECT_EQ(bytes, imu_sent[msg.header().seq()]) << "imu #" << msg.header().seq();
      EXPECT_EQ(m->publish_time_ns, static_cast<uint64_t>(msg.header().stamp_ns()));
      imu_rec[msg.header().seq()] = bytes;
      expected.push_back({"imu", m->sequence, testing::to_json(msg), "",
                          std::to_string(msg.header().stamp_ns())});
    } else {
      const auto msg =
          deserialize<msg::AttitudeEstimatePubSubType, msg::AttitudeEstimate>(m->data, m->size);
      EXPECT_EQ(bytes, att_sent[msg.header().seq()]) << "attitude #" << msg.header().seq();
      EXPECT_EQ(m->publish_time_ns, static_cast<uint64_t>(msg.header().stamp_ns()));
      att_rec[msg.header().seq()] = bytes;
      expected.push_back({"attitude/parallel_kf", m->sequence, testing::to_json(msg), "",
                          std::to_string(msg.header().stamp_ns())});
    }
  }
  EXPECT_EQ(att_rec.size(), static_cast<size_t>(kAttitude));
  EXPECT_GE(static_cast<double>(imu_rec.size()), kMinBestEffortFraction * kImu);
  EXPECT_EQ(rstats.written, imu_rec.size() + att_rec.size());

  // AND the independent reader agrees (framing, CRCs, indexes, decoded values)
  testing::write_expected(file, static_cast<int64_t>(imu_rec.size() + att_rec.size()), 1,
                          "{\"imu\":{\"schema\":\"poise::msg::ImuSample\",\"metadata\":{"
                          "\"reliability\":\"BEST_EFFORT\"}},\"attitude/parallel_kf\":{\"count\":" +
                              std::to_string(kAttitude) + "}}",
                          expected);
  const auto validation = testing::run_node_validator(dir);
  if (validation.skip_reason.empty()) {
    EXPECT_EQ(validation.exit_code, 0) << validation.output;
    std::printf("%s", validation.output.c_str());
  } else {
    std::printf("independent validation not run: %s\n", validation.skip_reason.c_str());
  }

  // WHEN the file is replayed (recorded timing) to typed subscribers
  Collector<msg::ImuSamplePubSubType> imu_got;
  Collector<msg::AttitudeEstimatePubSubType> att_got;
  {
    dds::Participant sub({lease.id(), kProfile, "", "test_sub"});
    dds::Reader<msg::ImuSamplePubSubType> imu_reader(
        sub, "imu", [&](const msg::ImuSample& m, const auto&) { imu_got.add(m); });
    dds::Reader<msg::AttitudeEstimatePubSubType> att_reader(
        sub, "attitude/parallel_kf",
        [&](const msg::AttitudeEstimate& m, const auto&) { att_got.add(m); });
    ReplayOptions po;
    po.input = file;
    po.domain = lease.id();
    po.participant_profile = kProfile;
    po.wait_for_subscribers_s = 15.0;
    std::ostringstream plog;
    po.log = &plog;
    const ReplayStats ps = replay(po);
    EXPECT_EQ(ps.schedule.delivered, imu_rec.size() + att_rec.size()) << plog.str();
    EXPECT_EQ(ps.write_failures, 0u);
    poise::testing::wait_until(
        [&] { return att_got.size() == att_rec.size() && imu_got.size() == imu_rec.size(); },
        kDeliveryTimeout);
  }
  // THEN subscribers get the recorded bytes
  EXPECT_EQ(att_got.size(), att_rec.size());
  EXPECT_GE(static_cast<double>(imu_got.size()),
            kMinBestEffortFraction * static_cast<double>(imu_rec.size()));
  for (const auto& [seq, bytes] : att_got.by_seq) {
    EXPECT_EQ(bytes, att_rec[seq]) << "attitude #" << seq;
  }
  for (const auto& [seq, bytes] : imu_got.by_seq) {
    EXPECT_EQ(bytes, imu_rec[seq]) << "imu #" << seq;
  }
}

// Issue 16: ROS 2 topics (rt/..., the types of idl/ros2) are recorded like poise's own: verbatim
// payloads, the ROS IDL as the omgidl schema, publish_time = header.stamp {sec, nanosec} in ns.
TEST(RecordReplay, GivenRos2TopicsWhenRecordedThenSchemaIsTheRosIdlAndPublishTimeTheHeaderStamp) {
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("dds_ros2");
  ASSERT_FALSE(dir.empty());
  const std::string file = dir + "/ros2.mcap";
  const std::string topic = "rt/poise/parallel_kf/imu";
  constexpr int kCount = 20;
  RecorderOptions ro = testing::recorder_options(file, lease.id(), kProfile);
  ro.topics = {topic};
  testing::RecorderThread recorder(ro);
  std::map<int64_t, std::vector<uint8_t>> sent;  // by header stamp, ns
  {
    dds::Participant pub({lease.id(), kProfile, "", "test_pub"});
    dds::Writer<sensor_msgs::msg::dds_::Imu_PubSubType> imu(pub, topic, dds::QosKind::kEstimate);
    ASSERT_TRUE(recorder.matched(
        poise::testing::wait_until([&] { return recorder->subscribed() == 1 && imu.matched() > 0; }, kMatchTimeout),
        "recorder did not subscribe/match within the timeout"));
    for (int i = 0; i < kCount; ++i) {
      sensor_msgs::msg::dds_::Imu_ m;
      m.header().stamp().sec(1'700'000'000 + i);
      m.header().stamp().nanosec(123'456'789U);
      m.header().frame_id("imu_link");
      m.orientation().w(1.0);
      m.angular_velocity().z(0.01 * i);
      sent[(1'700'000'000LL + i) * 1'000'000'000LL + 123'456'789LL] =
          testing::serialize<sensor_msgs::msg::dds_::Imu_PubSubType>(m);
      imu.write(m);
    }
    poise::testing::wait_until([&] { return recorder->written() >= kCount; }, kDeliveryTimeout);
  }
  const RecorderStats rstats = recorder.stop();
  ASSERT_TRUE(rstats.error.empty()) << rstats.error;
  McapReader reader = McapReader::open_file(file);
  reader.verify();
  ASSERT_TRUE(reader.report().complete);
  ASSERT_EQ(reader.channels().size(), 1U);
  const Channel& channel = reader.channels().begin()->second;
  EXPECT_EQ(channel.topic, topic);
  EXPECT_EQ(channel.metadata.at("publish_time"), "header.stamp");
  const auto& schema = reader.schemas().at(channel.schema_id);
  EXPECT_EQ(schema.name, "sensor_msgs::msg::dds_::Imu_");
  EXPECT_EQ(schema.encoding, "omgidl");
  const std::string text(schema.data.begin(), schema.data.end());
  EXPECT_NE(text.find("module sensor_msgs"), std::string::npos) << text;
  EXPECT_NE(text.find("struct Time_"), std::string::npos) << "self-contained: " << text;
  int n = 0;
  MessageCursor cursor = reader.messages();
  while (const MessageView* m = cursor.next()) {
    const auto it = sent.find(static_cast<int64_t>(m->publish_time_ns));
    ASSERT_NE(it, sent.end()) << "publish_time " << m->publish_time_ns << " is no header stamp sent";
    EXPECT_EQ(std::vector<uint8_t>(m->data, m->data + m->size), it->second);
    ++n;
  }
  EXPECT_EQ(n, kCount) << "reliable: every message";
}

TEST(RecordReplay, KillMinus9LeavesEveryMessageOlderThanTheChunkAgeReadable) {
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("crash");
  const std::string file = dir + "/crash.mcap";
  constexpr int kMessages = 200;
  // GIVEN `poise record` running in a child process
  poise::testing::Child child({tool(), "record", "-o", file, "attitude/crash", "--domain",
                               std::to_string(lease.id()), "--dds-profile", kProfile});
  dds::Participant pub({lease.id(), kProfile, "", "test_pub"});
  dds::Writer<msg::AttitudeEstimatePubSubType> writer(pub, "attitude/crash");
  ASSERT_TRUE(writer.wait_for_readers(1, kMatchTimeout)) << child.output();
  // WHEN it receives 200 reliable messages and then nothing
  for (int i = 0; i < kMessages; ++i) {
    writer.write(testing::make_attitude(static_cast<uint32_t>(i), 1000 + i));
    std::this_thread::sleep_for(2ms);
  }
  // THEN (without being stopped) it flushes them to the file within the chunk age limit...
  auto count_in_file = [&file]() -> uint64_t {
    try {
      return McapReader::open_file(file).report().messages;
    } catch (const std::exception&) {
      return 0;
    }
  };
  const bool flushed =
      poise::testing::wait_until([&] { return count_in_file() == kMessages; }, kDeliveryTimeout);
  EXPECT_TRUE(flushed) << "file holds " << count_in_file() << "\n" << child.output();
  // ...and after kill -9 they are all readable, with the file reported as recovered
  child.signal(SIGKILL);
  child.wait_for(5s);
  const McapReader reader = McapReader::open_file(file);
  EXPECT_FALSE(reader.report().complete);
  EXPECT_TRUE(reader.report().recovered);
  EXPECT_EQ(reader.report().messages, static_cast<uint64_t>(kMessages));
  std::string problems;
  for (const auto& p : reader.report().problems) {
    problems += p + "\n";
  }
  EXPECT_NE(problems.find("no Data End record: recovered 200 messages"), std::string::npos)
      << problems;
  // AND `poise info` says so (exit 3), and `poise replay` replays the recovered part (exit 3
  // without --allow-damaged, as its help says; issue 33)
  const auto info = poise::testing::run({tool(), "info", file}, 30s);
  EXPECT_EQ(info.exit_code, 3) << info.output;
  EXPECT_NE(info.output.find("RECOVERED"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("attitude/crash"), std::string::npos) << info.output;
  const auto rep = poise::testing::run({tool(), "replay", file, "--as-fast-as-possible", "--wait",
                                        "0", "--domain", std::to_string(lease.id()), "--dds-profile",
                                        kProfile},
                                       30s);
  EXPECT_EQ(rep.exit_code, 3) << rep.output;
  EXPECT_NE(rep.output.find("incomplete"), std::string::npos) << rep.output;
  EXPECT_NE(rep.output.find("published 200 messages"), std::string::npos) << rep.output;
}

TEST(RecordReplay, SplitSizeStartsNewCompleteFilesWithoutLosingMessages) {
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("split");
  constexpr int kMessages = 300;
  constexpr uint64_t kSplitBytes = 30 * 1024;
  RecorderOptions ro = testing::recorder_options(dir + "/split.mcap", lease.id(), kProfile);
  ro.topics = {"attitude/split"};
  ro.split_size_bytes = kSplitBytes;
  ro.writer.chunk_size_bytes = 8 * 1024;
  testing::RecorderThread recorder(ro);
  RecorderStats stats;
  {
    dds::Participant pub({lease.id(), kProfile, "", "test_pub"});
    dds::Writer<msg::AttitudeEstimatePubSubType> writer(pub, "attitude/split");
    const bool matched = writer.wait_for_readers(1, kMatchTimeout);
    if (matched) {
      for (int i = 0; i < kMessages; ++i) {
        writer.write(testing::make_attitude(static_cast<uint32_t>(i), 1000 + i));
        std::this_thread::sleep_for(1ms);  // stay within the writer's keep-last history
      }
      poise::testing::wait_until([&] { return recorder->written() >= kMessages; },
                                 kDeliveryTimeout);
    }
    stats = recorder.stop();
    ASSERT_TRUE(matched) << recorder.log();
  }
  ASSERT_TRUE(stats.error.empty()) << stats.error;
  ASSERT_GE(stats.files.size(), 3u);
  uint64_t total = 0;
  uint32_t next_seq = 0;
  for (size_t i = 0; i < stats.files.size(); ++i) {
    EXPECT_EQ(stats.files[i], split_file_name(ro.output, static_cast<int>(i)));
    const McapReader r = McapReader::open_file(stats.files[i]);
    EXPECT_TRUE(r.report().complete) << stats.files[i];
    EXPECT_EQ(r.channels().size(), 1u) << stats.files[i];
    total += r.report().messages;
    MessageCursor cursor = r.messages();
    while (const MessageView* m = cursor.next()) {
      const auto msg =
          deserialize<msg::AttitudeEstimatePubSubType, msg::AttitudeEstimate>(m->data, m->size);
      EXPECT_EQ(msg.header().seq(), next_seq++);  // reliable: in order, none missing
    }
  }
  EXPECT_EQ(total, static_cast<uint64_t>(kMessages));
}

// Issue 37: a recorder that matched the IMU writer 2.4 s late said "lost 0" while it had missed
// 489 samples. The writer's first sample to reach the recorder carries its DDS sequence number;
// everything below it was written before the match.
TEST(RecordReplay, GivenAWriterThatWroteBeforeTheRecorderMatchedWhenRecordedThenThoseSamplesAreReportedMissedBeforeMatch) {
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("before_match");
  constexpr int kBefore = 37;  // written while no recorder exists (the oracle: our own count)
  constexpr int kAfter = 50;   // written once the recorder matched
  dds::Participant pub({lease.id(), kProfile, "", "test_pub"});
  // Reliable, volatile: a late reader gets nothing written before it matched, and everything after.
  dds::Writer<msg::AttitudeEstimatePubSubType> writer(pub, "attitude/late");
  // GIVEN a writer that has written kBefore samples with nobody listening
  for (int i = 0; i < kBefore; ++i) {
    writer.write(testing::make_attitude(static_cast<uint32_t>(i), 1000 + i));
  }
  // WHEN a recorder starts, matches it, and kAfter more are written
  RecorderOptions ro = testing::recorder_options(dir + "/late.mcap", lease.id(), kProfile);
  ro.topics = {"attitude/late"};
  testing::RecorderThread recorder(ro);
  const bool matched = writer.wait_for_readers(1, kMatchTimeout);
  ASSERT_TRUE(recorder.matched(matched, "recorder did not match the writer"));
  for (int i = kBefore; i < kBefore + kAfter; ++i) {
    writer.write(testing::make_attitude(static_cast<uint32_t>(i), 1000 + i));
    std::this_thread::sleep_for(1ms);
  }
  poise::testing::wait_until([&] { return recorder->written() >= kAfter; }, kDeliveryTimeout);
  const RecorderStats stats = recorder.stop();
  ASSERT_TRUE(stats.error.empty()) << stats.error;
  // THEN the samples from before the match are reported as such, not as a gap, and not as 0
  const TopicStats& t = stats.topics.at("attitude/late");
  EXPECT_EQ(t.received, static_cast<uint64_t>(kAfter)) << recorder.log();
  EXPECT_EQ(t.before_match, static_cast<uint64_t>(kBefore));
  EXPECT_EQ(t.gaps, 0U);
  EXPECT_EQ(stats.before_match, static_cast<uint64_t>(kBefore));
  // and the file holds exactly the samples after the match (header.seq kBefore ...)
  const McapReader r = McapReader::open_file(dir + "/late.mcap");
  MessageCursor cursor = r.messages();
  uint32_t next_seq = kBefore;
  while (const MessageView* m = cursor.next()) {
    const auto msg = deserialize<msg::AttitudeEstimatePubSubType, msg::AttitudeEstimate>(m->data, m->size);
    EXPECT_EQ(msg.header().seq(), next_seq++);
  }
  EXPECT_EQ(next_seq, static_cast<uint32_t>(kBefore + kAfter));
}

TEST(RecordCli, DurationEndsTheRecordingWithACompleteFile) {
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("duration");
  const std::string file = dir + "/empty.mcap";
  const auto rec = poise::testing::run({tool(), "record", "-o", file, "--all", "--duration", "1",
                                        "--domain", std::to_string(lease.id()), "--dds-profile",
                                        kProfile},
                                       30s);
  EXPECT_EQ(rec.exit_code, 0) << rec.output;
  const auto info = poise::testing::run({tool(), "info", file, "--verify"}, 30s);
  EXPECT_EQ(info.exit_code, 0) << info.output;
  EXPECT_NE(info.output.find("complete (summary and footer valid)"), std::string::npos)
      << info.output;
  EXPECT_NE(info.output.find("messages:  0"), std::string::npos) << info.output;
  // Ctrl-C (SIGINT) also ends it with a complete file.
  const std::string file2 = dir + "/interrupted.mcap";
  poise::testing::Child child({tool(), "record", "-o", file2, "imu", "--domain",
                               std::to_string(lease.id()), "--dds-profile", kProfile});
  ASSERT_TRUE(poise::testing::wait_until(
      [&] { return child.output().find("waiting for publishers") != std::string::npos; }, 15s))
      << child.output();
  child.signal(SIGINT);
  EXPECT_EQ(child.wait_for(15s), std::optional<int>(0)) << child.output();
  EXPECT_TRUE(McapReader::open_file(file2).report().complete);
}

TEST(RecordCli, DiskFullAndBadFilesGiveClearErrors) {
  poise::testing::DomainLease lease;
  // Recording to a full device stops at once with the reason.
  const auto full = poise::testing::run({tool(), "record", "-o", "/dev/full", "imu", "--domain",
                                         std::to_string(lease.id()), "--dds-profile", kProfile},
                                        30s);
  EXPECT_EQ(full.exit_code, 1) << full.output;
  EXPECT_NE(full.output.find("No space left on device"), std::string::npos) << full.output;
  // A file that is not MCAP.
  const std::string dir = testing::cases_dir("cli");
  const std::string junk = dir + "/junk.mcap";
  std::ofstream(junk) << "this is not an mcap file at all, not even close";
  const auto info = poise::testing::run({tool(), "info", junk}, 30s);
  EXPECT_EQ(info.exit_code, 1) << info.output;
  EXPECT_NE(info.output.find("not an MCAP file"), std::string::npos) << info.output;
  // Usage errors.
  const auto no_topics = poise::testing::run({tool(), "record", "-o", dir + "/x.mcap"}, 30s);
  EXPECT_EQ(no_topics.exit_code, 2) << no_topics.output;
  for (const char* cmd : {"info", "record", "replay"}) {
    const auto help = poise::testing::run({tool(), cmd, "--help"}, 30s);
    EXPECT_EQ(help.exit_code, 0) << help.output;
  }
}

// Issue 19 item 7: on a full disk the counts are exact: written = what the file holds, every other
// valid sample received is counted lost, and the exit code is 1. The limit is the child's own
// RLIMIT_FSIZE (prlimit, SIGXFSZ ignored so that write() fails with EFBIG): no root, no device.
TEST(RecordCli, GivenAFileSizeLimitWhenItIsReachedThenWrittenIsWhatTheFileHoldsAndTheRestIsLost) {
  const std::string prlimit = testing::find_on_path("prlimit");
  if (prlimit.empty()) {
    POISE_SKIP("prlimit (util-linux) not found on PATH");
  }
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("fsize");
  const std::string file = dir + "/limited.mcap";
  constexpr int kLimitBytes = 300000;  // about one 1-second chunk of the stream below
  constexpr int kMessages = 3000;      // at 1 kHz: 3 s, several chunks' worth
  poise::dds::ParticipantOptions popts;
  popts.domain = lease.id();
  popts.profile = kProfile;
  poise::dds::Participant participant(popts);
  poise::dds::Writer<msg::AttitudeEstimatePubSubType> writer(participant, "attitude/full");
  poise::testing::Child child(
      {"/bin/sh", "-c",
       "trap '' XFSZ; exec \"$0\" --fsize=" + std::to_string(kLimitBytes) +
           " \"$1\" record -o \"$2\" attitude/full --domain \"$3\" --dds-profile \"$4\"",
       prlimit, tool(), file, std::to_string(lease.id()), kProfile});
  ASSERT_TRUE(writer.wait_for_readers(1, kMatchTimeout)) << child.output();
  for (int i = 0; i < kMessages && !child.wait_for(0s).has_value(); ++i) {
    writer.write(testing::make_attitude(static_cast<uint32_t>(i), 1'000'000'000LL + i));
    std::this_thread::sleep_for(1ms);
  }
  const auto code = child.wait_for(15s);
  ASSERT_TRUE(code.has_value()) << "the recorder stops at the write error\n" << child.output();
  EXPECT_EQ(*code, 1) << child.output();
  const std::string out = child.output();
  EXPECT_NE(out.find("File too large"), std::string::npos) << out;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      out, m,
      std::regex(R"(attitude/full \(poise::msg::AttitudeEstimate\): received (\d+), written (\d+), )"
                 R"(malformed 0, dropped 0, lost (\d+))")))
      << out;
  const uint64_t received = std::stoull(m[1]);
  const uint64_t written = std::stoull(m[2]);
  const uint64_t lost = std::stoull(m[3]);
  EXPECT_EQ(written + lost, received) << out;
  EXPECT_GT(lost, 0u) << out;
  const McapReader reader = McapReader::open_file(file);
  uint64_t in_file = 0;
  MessageCursor cursor = reader.messages();
  while (cursor.next() != nullptr) {
    ++in_file;
  }
  EXPECT_EQ(in_file, written) << out;
  EXPECT_NE(out.find("lost (received, not in the file because writing failed): " +
                     std::to_string(lost)),
            std::string::npos)
      << out;
  // issue 33: the error line said 1208 lost where the table said 1213
  EXPECT_NE(out.find("(" + std::to_string(lost) + " messages lost)"), std::string::npos) << out;
}

}  // namespace
}  // namespace poise::record
