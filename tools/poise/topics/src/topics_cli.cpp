// `poise topics`, `poise echo` and the hidden test publisher `poise dds-test-pub`.
#include "poise/cli/common.h"
#include "poise/dds/participant.h"
#include "poise/dds/sequence_gaps.h"
#include "poise/dds/topics.h"
#include "poise/schema/cdr.h"
#include "poise/schema/malformed.h"
#include "poise/schema/observer.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <fastdds/dds/topic/TopicDataType.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

namespace poise::cli {
namespace {

using Clock = std::chrono::steady_clock;
using schema::TopicObserver;

std::string hex(const std::vector<std::uint8_t>& bytes) {
  static const char* const kDigits = "0123456789abcdef";
  std::string out;
  out.reserve(bytes.size() * 2);
  for (const std::uint8_t b : bytes) {
    out += kDigits[b >> 4];
    out += kDigits[b & 0xF];
  }
  return out;
}

std::string json_string(const std::string& s) {
  schema::Value v;
  v.kind = schema::Value::Kind::kString;
  v.s = s;
  return schema::to_json(v);
}

const schema::TypeTable& type_table() {
  try {
    return schema::TypeTable::builtin();
  } catch (const schema::SchemaError& e) {
    throw Error(std::string("cannot load the IDL types: ") + e.what() +
                " (check POISE_IDL_DIR, or unset it to use the built-in types)");
  }
}

schema::ObserverOptions observer_options(int domain, const std::string& profile, const char* name) {
  schema::ObserverOptions o;
  o.domain = domain;
  o.profile = profile;
  o.name = name;
  return o;
}

// ---------------------------------------------------------------------------------------------
// poise echo

struct EchoOptions {
  std::string topic;
  int domain = 0;
  std::string profile;
  int count = 0;
  bool json = false;
  double timeout_s = 10.0;
};

struct Received {
  poise::dds::RawSample sample;
  std::int64_t source_timestamp_ns = 0;
  std::string problem;  // non-empty: rejected as malformed (payload_problem)
  std::uint64_t lost_before = 0;  // samples missing just before this one (header.seq gap)
};

// not split: one linear command (match the type, subscribe, print each sample, summarise) whose steps
// share the reader and its sequence-gap state.
void run_echo(const EchoOptions& o) {
  install_stop_handlers();
  const schema::TypeTable& table = type_table();
  TopicObserver observer(observer_options(o.domain, o.profile, "poise-echo"));
  std::fprintf(stderr, "poise echo: waiting up to %.1f s for a writer of '%s' on domain %d\n",
               o.timeout_s, o.topic.c_str(), o.domain);
  const auto writer = observer.wait_for_writer(
      o.topic, std::chrono::milliseconds(static_cast<std::int64_t>(o.timeout_s * 1000.0)),
      [] { return stop_requested(); });
  if (!writer) {
    if (stop_requested()) {
      return;
    }
    std::string known;
    for (const auto& w : observer.writers()) {
      known += (known.empty() ? "" : ", ") + w.topic;
    }
    throw Error("no writer of topic '" + o.topic + "' on domain " + std::to_string(o.domain) +
                " within " + std::to_string(o.timeout_s) + " s (" +
                (known.empty() ? std::string("no writers seen at all: is the publisher running on "
                                             "this domain and DDS profile?")
                               : "topics seen: " + known) +
                ")");
  }
  const bool decodable = table.find_struct(writer->type) != nullptr;
  std::fprintf(stderr, "poise echo: '%s' has type %s%s\n", o.topic.c_str(), writer->type.c_str(),
               decodable ? "" : " (not a known IDL type: printing raw bytes as hex)");

  std::mutex mutex;
  std::condition_variable cv;
  std::deque<Received> queue;
  std::uint64_t dropped = 0;                 // guarded by mutex
  constexpr std::size_t kMaxQueued = 10000;  // a slow terminal drops samples rather than memory
  // Loss on the way (a best-effort topic on a busy link): gaps in header.seq per instance and
  // writer, as `poise topics` counts them (types whose header.seq numbers their messages: not
  // FilterDiagnostics, not ROS 2 types; header_seq_counts_messages).
  const bool poise_type = poise::dds::header_seq_counts_messages(writer->type);
  poise::dds::SequenceGaps gaps;  // guarded by mutex
  const auto enqueue = [&](const poise::dds::RawSample& s,
                           const eprosima::fastdds::dds::SampleInfo& info, const std::string& problem) {
    std::lock_guard<std::mutex> lock(mutex);
    std::uint64_t lost = 0;
    // only valid payloads count: a malformed one's header.seq is whatever its bytes say
    if (const auto seq = poise_type && problem.empty() ? poise::dds::header_seq_from_payload(s.data) : std::nullopt) {
      lost = gaps.on_sample(poise::dds::handle_key(info.instance_handle), *seq, poise::dds::writer_key(info)).lost;
    }
    if (queue.size() < kMaxQueued) {
      queue.push_back({s, info.source_timestamp.to_ns(), problem, lost});
    } else {
      ++dropped;
    }
    cv.notify_one();
  };
  // Malformed payloads (checked against the IDL type by the observer) arrive with their reason.
  observer.subscribe(
      *writer, &table,
      [&](const poise::dds::RawSample& s, const eprosima::fastdds::dds::SampleInfo& info) {
        enqueue(s, info, "");
      },
      {}, enqueue);

  int printed = 0;
  std::uint64_t failed = 0;
  while (!stop_requested() && (o.count == 0 || printed < o.count)) {
    Received r;
    {
      std::unique_lock<std::mutex> lock(mutex);
      cv.wait_for(lock, std::chrono::milliseconds(100), [&queue] { return !queue.empty(); });
      if (queue.empty()) {
        continue;
      }
      r = std::move(queue.front());
      queue.pop_front();
    }
    std::string body;
    bool ok = r.problem.empty();
    std::string error = r.problem;
    if (ok && decodable) {
      try {
        const schema::Value v = schema::decode(table, writer->type, r.sample.data);
        body = o.json ? schema::to_json(v) : schema::to_text(v);
      } catch (const schema::DecodeError& e) {
        ok = false;
        error = e.what();
      }
    }
    if (!ok) {
      ++failed;
      std::fprintf(stderr, "poise echo: malformed sample of %zu bytes rejected (#%llu): %s\n",
                   r.sample.data.size(), static_cast<unsigned long long>(failed), error.c_str());
      continue;
    }
    ++printed;
    if (o.json) {
      std::string line = "{\"topic\":" + json_string(o.topic) + ",\"type\":" +
                         json_string(writer->type) +
                         ",\"size\":" + std::to_string(r.sample.data.size()) +
                         ",\"source_timestamp_ns\":" + std::to_string(r.source_timestamp_ns) +
                         ",\"lost_before\":" + (poise_type ? std::to_string(r.lost_before) : std::string("null"));
      line += decodable ? ",\"data\":" + body : ",\"data\":null,\"hex\":\"" + hex(r.sample.data) + "\"";
      line += "}\n";
      std::fputs(line.c_str(), stdout);
    } else {
      std::printf("--- %s [%s] #%d, %zu bytes%s\n", o.topic.c_str(), writer->type.c_str(), printed,
                  r.sample.data.size(),
                  r.lost_before == 0 ? "" : (", " + std::to_string(r.lost_before) + " lost before it (seq gap)").c_str());
      std::fputs(decodable ? body.c_str() : (hex(r.sample.data) + "\n").c_str(), stdout);
    }
    std::fflush(stdout);
  }
  std::lock_guard<std::mutex> lock(mutex);
  const poise::dds::SequenceGaps::Totals t = gaps.totals();
  const std::string lost = poise_type ? std::to_string(t.lost) + " lost on the way (" + std::to_string(t.gaps) +
                                            " header.seq gap(s), " + std::to_string(t.restarts) + " publisher restart(s))"
                                      : std::string("loss unknown (not a poise type: no header.seq)");
  std::fprintf(stderr,
               "poise echo: %d sample(s) printed, %s, %llu malformed rejected, %llu dropped (output "
               "too slow)\n",
               printed, lost.c_str(), static_cast<unsigned long long>(failed),
               static_cast<unsigned long long>(dropped));
}

// ---------------------------------------------------------------------------------------------
// poise topics

struct TopicsOptions {
  int domain = 0;
  std::string profile;
  double duration_s = 2.0;
  /// Discovery before the sampling window: Fast DDS announces a participant every 3 s after its
  /// first few announcements, and a writer was measured taking up to 2.4 s to be seen on an idle
  /// loopback (longer on a loaded machine), so a shorter wait lists a domain incompletely.
  double discovery_s = 3.0;
  bool json = false;
};

struct TopicStats {
  std::mutex mutex;
  /// Sequence gaps of poise types (header.seq), per instance (sensor_id) and writer.
  bool poise_type = false;
  poise::dds::SequenceGaps gaps;
  std::uint64_t samples = 0;
  std::uint64_t malformed = 0;  // rejected: not a valid payload of the topic's type
  std::uint64_t bytes = 0;
  Clock::time_point first;
  Clock::time_point last;
};

std::string fixed(double v, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  return buf;
}

// not split: one linear command (discover, sample for the window, tabulate, print) whose steps share
// the observer and the per-topic readers it creates.
void run_topics(const TopicsOptions& o) {
  install_stop_handlers();
  const schema::TypeTable& table = type_table();
  TopicObserver observer(observer_options(o.domain, o.profile, "poise-topics"));
  std::fprintf(stderr, "poise topics: discovering domain %d for %.1f s, then sampling for %.1f s\n", o.domain,
               o.discovery_s, o.duration_s);
  std::map<std::string, std::shared_ptr<TopicStats>> stats;  // by topic
  const auto start = Clock::now();
  // Writers are subscribed as soon as they are seen; samples count from the window's start.
  const auto window = start + std::chrono::duration_cast<Clock::duration>(
                                  std::chrono::duration<double>(o.discovery_s));
  const auto end = window + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(o.duration_s));
  while (Clock::now() < end && !stop_requested()) {
    for (const auto& w : observer.writers()) {
      if (stats.count(w.topic) != 0) {
        continue;
      }
      auto s = std::make_shared<TopicStats>();
      s->poise_type = poise::dds::header_seq_counts_messages(w.type);
      stats[w.topic] = s;
      try {
        observer.subscribe(w, &table,
                           [s, window](const poise::dds::RawSample& sample,
                                       const eprosima::fastdds::dds::SampleInfo& info) {
                             const auto now = Clock::now();
                             if (now < window) {
                               return;  // still discovering
                             }
                             std::lock_guard<std::mutex> lock(s->mutex);
                             const auto seq = s->poise_type
                                                  ? poise::dds::header_seq_from_payload(sample.data)
                                                  : std::nullopt;
                             if (seq) {
                               s->gaps.on_sample(poise::dds::handle_key(info.instance_handle), *seq,
                                                 poise::dds::writer_key(info));
                             }
                             if (s->samples == 0) {
                               s->first = now;
                             }
                             s->last = now;
                             ++s->samples;
                             s->bytes += sample.data.size();
                           },
                           {},
                           [s, window](const poise::dds::RawSample& /*sample*/,
                                       const eprosima::fastdds::dds::SampleInfo& /*info*/,
                                       const std::string& /*problem*/) {
                             if (Clock::now() < window) {
                               return;  // still discovering
                             }
                             std::lock_guard<std::mutex> lock(s->mutex);
                             ++s->malformed;
                           });
      } catch (const std::exception& e) {
        std::fprintf(stderr, "poise topics: cannot sample '%s': %s\n", w.topic.c_str(), e.what());
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }

  struct Row {
    std::string topic;
    std::set<std::string> types;
    int writers = 0;
    std::uint64_t samples = 0;
    std::uint64_t malformed = 0;
    std::optional<std::uint64_t> lost;  // sequence gaps (poise types only)
    double rate_hz = 0.0;
    double bytes_per_s = 0.0;
  };
  std::map<std::string, Row> rows;
  for (const auto& w : observer.writers()) {
    Row& r = rows[w.topic];
    r.topic = w.topic;
    r.types.insert(w.type);
    ++r.writers;
  }
  for (auto& [topic, r] : rows) {
    const auto it = stats.find(topic);
    if (it == stats.end()) {
      continue;
    }
    std::lock_guard<std::mutex> lock(it->second->mutex);
    const TopicStats& s = *it->second;
    r.samples = s.samples;
    r.malformed = s.malformed;
    if (s.poise_type) {
      r.lost = s.gaps.totals().lost;
    }
    const double span_s = std::chrono::duration<double>(s.last - s.first).count();
    if (s.samples >= 2 && span_s > 0.0) {
      // Rate over the sampled span: (n - 1) intervals; bytes/s from the mean sample size.
      r.rate_hz = static_cast<double>(s.samples - 1) / span_s;
      r.bytes_per_s = r.rate_hz * static_cast<double>(s.bytes) / static_cast<double>(s.samples);
    }
  }

  const auto join = [](const std::set<std::string>& types) {
    std::string out;
    for (const auto& t : types) {
      out += (out.empty() ? "" : ",") + t;
    }
    return out;
  };
  if (o.json) {
    std::string out = "{\"domain\":" + std::to_string(o.domain) +
                      ",\"duration_s\":" + fixed(o.duration_s, 3) + ",\"topics\":[";
    bool first = true;
    for (const auto& [topic, r] : rows) {
      out += first ? "" : ",";
      first = false;
      out += "{\"topic\":" + json_string(topic) + ",\"type\":" + json_string(join(r.types)) +
             ",\"writers\":" + std::to_string(r.writers) +
             ",\"samples\":" + std::to_string(r.samples) + ",\"rate_hz\":" + fixed(r.rate_hz, 3) +
             ",\"bytes_per_s\":" + fixed(r.bytes_per_s, 1) +
             ",\"malformed\":" + std::to_string(r.malformed) +
             ",\"lost\":" + (r.lost ? std::to_string(*r.lost) : std::string("null")) + "}";
    }
    out += "]}\n";
    std::fputs(out.c_str(), stdout);
  } else {
    std::size_t topic_w = 5;
    std::size_t type_w = 4;
    for (const auto& [topic, r] : rows) {
      topic_w = std::max(topic_w, topic.size());
      type_w = std::max(type_w, join(r.types).size());
    }
    std::printf("%-*s  %-*s  %7s  %9s  %11s  %9s  %6s\n", static_cast<int>(topic_w), "TOPIC",
                static_cast<int>(type_w), "TYPE", "WRITERS", "RATE_HZ", "BYTES_PER_S", "MALFORMED",
                "LOST");
    for (const auto& [topic, r] : rows) {
      std::printf("%-*s  %-*s  %7d  %9s  %11s  %9llu  %6s\n", static_cast<int>(topic_w), topic.c_str(),
                  static_cast<int>(type_w), join(r.types).c_str(), r.writers,
                  fixed(r.rate_hz, 1).c_str(), fixed(r.bytes_per_s, 0).c_str(),
                  static_cast<unsigned long long>(r.malformed),
                  r.lost ? std::to_string(*r.lost).c_str() : "-");
    }
    if (rows.empty()) {
      std::printf("(no writers discovered on domain %d)\n", o.domain);
    }
  }
  std::fflush(stdout);
}

// ---------------------------------------------------------------------------------------------
// poise dds-test-pub (hidden): deterministic samples from the generated type support, for tests.

struct TestPubOptions {
  std::string type = "imu";
  std::string topic;
  std::string sensor_id = "imu0";
  int domain = 0;
  std::string profile;
  int count = 100;
  double rate_hz = 50.0;
  double wait_readers_s = 0.0;
  int seq_step = 1;  // header.seq advances by this per sample (> 1: gaps, as if samples were lost)
};

template <class PubSubType, class Fill>
void publish(const TestPubOptions& o, const std::string& default_topic, Fill fill) {
  poise::dds::ParticipantOptions popts;
  popts.domain = o.domain;
  popts.profile = o.profile;
  popts.name = "poise-dds-test-pub";
  poise::dds::Participant participant(popts);
  const std::string topic = o.topic.empty() ? default_topic : o.topic;
  poise::dds::Writer<PubSubType> writer(participant, topic);
  if (o.wait_readers_s > 0.0 &&
      !writer.wait_for_readers(1, std::chrono::milliseconds(
                                      static_cast<std::int64_t>(o.wait_readers_s * 1000.0)))) {
    throw Error("no reader of '" + topic + "' matched within " + std::to_string(o.wait_readers_s) +
                " s");
  }
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / o.rate_hz));
  auto next = Clock::now();
  for (int i = 0; i < o.count && !stop_requested(); ++i) {
    typename PubSubType::type msg;
    msg.header().stamp_ns(1000000000LL + 1000000LL * i);
    msg.header().seq(static_cast<std::uint32_t>(i) * static_cast<std::uint32_t>(o.seq_step));
    msg.sensor_id(o.sensor_id);
    fill(msg, i);
    writer.write(msg);
    next += period;
    std::this_thread::sleep_until(next);
  }
}

// The full payload (encapsulation included) of a sample, as the generated type support writes it.
template <class PubSubType>
std::vector<std::uint8_t> serialized(typename PubSubType::type& msg) {
  PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.m_typeSize);
  if (!type.serialize(&msg, &payload)) {
    throw Error("cannot serialize a sample");
  }
  return {payload.data, payload.data + payload.length};
}

// The type support of a careless or hostile peer: any bytes go on the wire verbatim (0 bytes
// included) under a poise type name, keyed like the real type, but it never computes a key, so
// samples carry no key hash and every reader must derive the instance from the bytes themselves.
class CarelessType : public eprosima::fastdds::dds::TopicDataType {
 public:
  explicit CarelessType(const char* type_name) {
    setName(type_name);
    m_typeSize = 4096;
    m_isGetKeyDefined = true;
    auto_fill_type_object(false);
    auto_fill_type_information(false);
  }
  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override {
    const auto& bytes = static_cast<poise::dds::RawSample*>(data)->data;
    if (bytes.size() > payload->max_size) {
      return false;
    }
    std::copy(bytes.begin(), bytes.end(), payload->data);
    payload->length = static_cast<std::uint32_t>(bytes.size());
    return true;
  }
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* /*payload*/,
                   void* /*data*/) override {
    return false;  // write-only
  }
  std::function<std::uint32_t()> getSerializedSizeProvider(void* data) override {
    return [data] {
      return static_cast<std::uint32_t>(static_cast<poise::dds::RawSample*>(data)->data.size());
    };
  }
  void* createData() override { return new poise::dds::RawSample(); }
  void deleteData(void* data) override { delete static_cast<poise::dds::RawSample*>(data); }
  bool getKey(void* /*data*/, eprosima::fastrtps::rtps::InstanceHandle_t* /*handle*/,
              bool /*force_md5*/) override {
    return false;
  }
};

// The stamp of valid sample i: 1 s, then one period of --rate per sample, so the stamps advance
// as the samples are sent (a receiver judging their age sees none grow old).
std::int64_t malformed_pub_stamp_ns(const TestPubOptions& o, int i) {
  return 1000000000LL + std::llround(1e9 * static_cast<double>(i) / o.rate_hz);
}

// The valid sample i of `imu-malformed`: level, facing magnetic north, with pressure (every
// estimator node can use it).
std::vector<std::uint8_t> valid_imu_payload(const TestPubOptions& o, int i) {
  poise::msg::ImuSample m;
  m.header().stamp_ns(malformed_pub_stamp_ns(o, i));
  m.header().seq(static_cast<std::uint32_t>(i));
  m.header().frame_id("body");
  m.sensor_id(o.sensor_id);
  m.accel_mps2().z(9.81);
  m.mag_ut().y(30.0);
  m.mag_ut().z(-40.0);
  m.pressure_pa(101325.0);
  m.valid().accel(true);
  m.valid().gyro(true);
  m.valid().mag(true);
  m.valid().pressure(true);
  return serialized<poise::msg::ImuSamplePubSubType>(m);
}

// The valid sample i of `vision-malformed`: a camera 1 m above the world origin, level.
std::vector<std::uint8_t> valid_vision_payload(const TestPubOptions& o, int i) {
  poise::msg::VisionPose m;
  const std::int64_t stamp_ns = malformed_pub_stamp_ns(o, i);
  m.header().stamp_ns(stamp_ns);
  m.header().seq(static_cast<std::uint32_t>(i));
  m.header().frame_id("world");
  m.sensor_id(o.sensor_id);
  m.capture_stamp_ns(stamp_ns);
  m.pose_world_camera().position_m().z(1.0);
  m.pose_world_camera().orientation().w(1.0);
  m.pose_world_body().orientation().w(1.0);
  for (std::size_t k = 0; k < 36; k += 7) {
    m.covariance()[k] = 1e-4;  // diagonal: 1 cm, 0.01 rad
  }
  m.tag_ids({0});
  return serialized<poise::msg::VisionPosePubSubType>(m);
}

// Alternates a valid sample (seq i, the given sensor_id) of the type (`imu-malformed`: ImuSample
// on `imu`, `vision-malformed`: VisionPose on `vision_pose`) with malformed_variants() of it
// (cycling), on a reliable writer; count valid and count malformed samples. Waits for
// acknowledgments.
void run_malformed_pub(const TestPubOptions& o) {
  const bool vision = o.type == "vision-malformed";
  poise::dds::ParticipantOptions popts;
  popts.domain = o.domain;
  popts.profile = o.profile;
  popts.name = "poise-dds-test-pub-malformed";
  poise::dds::Participant participant(popts);
  const std::string topic_name = !o.topic.empty() ? o.topic : vision ? "vision_pose" : "imu";
  eprosima::fastdds::dds::Topic* topic = participant.topic(
      topic_name, eprosima::fastdds::dds::TypeSupport(new CarelessType(
                      vision ? poise::dds::type_names::kVisionPose : poise::dds::type_names::kImuSample)));
  poise::dds::detail::MatchCounter matches;
  eprosima::fastdds::dds::DataWriter* writer = poise::dds::detail::create_writer(
      participant, topic, poise::dds::QosKind::kEstimate, &matches);
  if (o.wait_readers_s > 0.0 &&
      !poise::dds::detail::wait_matched(
          matches, 1, std::chrono::milliseconds(static_cast<std::int64_t>(o.wait_readers_s * 1000.0)))) {
    throw Error("no reader of '" + topic_name + "' matched within " +
                std::to_string(o.wait_readers_s) + " s");
  }
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / o.rate_hz));
  auto next = Clock::now();
  int valid = 0;
  int malformed = 0;
  for (int i = 0; i < o.count && !stop_requested(); ++i) {
    poise::dds::RawSample good{vision ? valid_vision_payload(o, i) : valid_imu_payload(o, i)};
    const auto variants = schema::malformed_variants(good.data);
    poise::dds::RawSample bad{variants[static_cast<std::size_t>(i) % variants.size()].bytes};
    valid += writer->write(&good) ? 1 : 0;
    malformed += writer->write(&bad) ? 1 : 0;
    next += period;
    std::this_thread::sleep_until(next);
  }
  writer->wait_for_acknowledgments(eprosima::fastrtps::Duration_t(5, 0));
  std::printf("published %d valid, %d malformed\n", valid, malformed);
  std::fflush(stdout);
  writer->set_listener(nullptr);
  participant.publisher()->delete_datawriter(writer);
}

void run_test_pub(const TestPubOptions& o) {
  install_stop_handlers();
  if (o.type == "imu-malformed" || o.type == "vision-malformed") {
    run_malformed_pub(o);
  } else if (o.type == "imu") {
    publish<poise::msg::ImuSamplePubSubType>(o, "imu", [](poise::msg::ImuSample& m, int i) {
      m.header().frame_id("body");
      m.accel_mps2().z(9.81);
      m.gyro_rps().x(0.001 * i);
      m.valid().accel(true);
      m.valid().gyro(true);
    });
  } else if (o.type == "diagnostics") {
    publish<poise::msg::FilterDiagnosticsPubSubType>(
        o, "diagnostics", [](poise::msg::FilterDiagnostics& m, int i) {
          m.component_name("dds_test_pub");
          poise::msg::Counter c;
          c.name("published");
          c.value(static_cast<std::uint64_t>(i));
          m.counters({c});
        });
  } else if (o.type == "attitude") {
    publish<poise::msg::AttitudeEstimatePubSubType>(
        o, "attitude/test", [](poise::msg::AttitudeEstimate& m, int i) {
          m.filter_id("test");
          m.q_world_body().w(1.0);
          m.yaw_rad(0.01 * i);
        });
  }
}

// ---------------------------------------------------------------------------------------------
// poise bench decode: schema-layer decoding speed (payload -> Value -> JSON / text).

void run_bench_decode(int iterations) {
  const schema::TypeTable& table = type_table();
  poise::msg::ImuSample imu;
  imu.sensor_id("imu0");
  imu.header().frame_id("body");
  poise::msg::FilterDiagnostics diag;  // a busy diagnostics sample: 6 sources, 20 counters
  diag.sensor_id("parallel_kf");
  for (int k = 0; k < 6; ++k) {
    poise::msg::SourceStatus st;
    st.source("source" + std::to_string(k));
    st.innovation({0.1, 0.2, 0.3});
    st.innovation_variance({0.01, 0.02, 0.03});
    diag.sources().push_back(st);
  }
  for (int k = 0; k < 20; ++k) {
    poise::msg::Counter c;
    c.name("rejected_reason_" + std::to_string(k));
    c.value(static_cast<std::uint64_t>(k));
    diag.counters().push_back(c);
  }
  const std::vector<std::pair<std::string, std::vector<std::uint8_t>>> cases = {
      {"poise::msg::ImuSample", serialized<poise::msg::ImuSamplePubSubType>(imu)},
      {"poise::msg::FilterDiagnostics",
       serialized<poise::msg::FilterDiagnosticsPubSubType>(diag)}};
  std::printf("%-30s %6s %12s %12s %12s\n", "TYPE", "BYTES", "DECODE_US", "+JSON_US", "+TEXT_US");
  for (const auto& [type, payload] : cases) {
    std::size_t sink = 0;
    const auto time_us = [&](int mode) {
      const auto t0 = Clock::now();
      for (int i = 0; i < iterations; ++i) {
        const schema::Value v = schema::decode(table, type, payload);
        sink += mode == 0 ? v.fields.size()
                          : (mode == 1 ? schema::to_json(v).size() : schema::to_text(v).size());
      }
      return std::chrono::duration<double, std::micro>(Clock::now() - t0).count() / iterations;
    };
    const double decode_us = time_us(0);
    const double json_us = time_us(1);
    const double text_us = time_us(2);
    std::printf("%-30s %6zu %12.2f %12.2f %12.2f\n", type.c_str(), payload.size(), decode_us,
                json_us, text_us);
    if (sink == 0) {
      std::printf("(nothing decoded)\n");
    }
  }
}

}  // namespace

void register_topic_commands(CLI::App& app) {
  CLI::App* bench = subcommand_group(app, "bench", "Benchmarks (figures printed, not asserted)");
  auto iterations = std::make_shared<int>(20000);
  CLI::App* b = bench->add_subcommand(
      "decode", "Schema-layer CDR decoding speed per sample (decode, +JSON, +text), in microseconds");
  b->add_option("--iterations", *iterations, "Samples decoded per figure")
      ->check(CLI::Range(1, 100000000))
      ->capture_default_str();
  b->callback([iterations] { run_bench_decode(*iterations); });

  auto echo = std::make_shared<EchoOptions>();
  CLI::App* e = app.add_subcommand(
      "echo", "Print the samples of a DDS topic, decoded with the IDL types (--json: one object per line)");
  e->add_option("topic", echo->topic, "Topic name, e.g. imu, attitude/parallel_kf")->required();
  add_domain_option(e, &echo->domain);
  add_dds_profile_option(e, &echo->profile);
  e->add_option("--count", echo->count, "Exit after this many samples (0: until Ctrl-C)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  e->add_flag("--json", echo->json, "One JSON object per sample and line");
  e->add_option("--timeout", echo->timeout_s, "Seconds to wait for a writer of the topic")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  e->callback([echo] { run_echo(*echo); });

  auto topics = std::make_shared<TopicsOptions>();
  CLI::App* t = app.add_subcommand(
      "topics", "List the topics with writers on a domain, with type, writer count, rate and bandwidth");
  add_domain_option(t, &topics->domain);
  add_dds_profile_option(t, &topics->profile);
  // bounded: the seconds become int64 nanoseconds (1e308 s would overflow)
  t->add_option("--duration", topics->duration_s, "Seconds to sample (after --discovery)")
      ->check(CLI::Range(1e-3, 86400.0))
      ->capture_default_str();
  t->add_option("--discovery", topics->discovery_s,
                "Seconds to discover writers before sampling (a writer can take up to ~3 s to be seen)")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  t->add_flag("--json", topics->json, "One JSON document instead of a table");
  t->callback([topics] { run_topics(*topics); });

  auto pub = std::make_shared<TestPubOptions>();
  CLI::App* p = app.add_subcommand("dds-test-pub", "Publish deterministic test samples (for tests)");
  p->group("");  // hidden from --help
  p->add_option("--type", pub->type,
                "imu | diagnostics | attitude | imu-malformed | vision-malformed (each valid "
                "ImuSample / VisionPose followed by a malformed one, reliable, no key hash)")
      ->check(CLI::IsMember({"imu", "diagnostics", "attitude", "imu-malformed", "vision-malformed"}))
      ->capture_default_str();
  p->add_option("--topic", pub->topic, "Topic name (default: imu, diagnostics, attitude/test, vision_pose)");
  p->add_option("--sensor-id", pub->sensor_id, "sensor_id of every sample")->capture_default_str();
  add_domain_option(p, &pub->domain);
  add_dds_profile_option(p, &pub->profile);
  p->add_option("--count", pub->count, "Samples to publish")->check(CLI::PositiveNumber);
  p->add_option("--rate", pub->rate_hz, "Samples per second")->check(CLI::Range(0.1, 10000.0));
  p->add_option("--wait-readers", pub->wait_readers_s,
                "Wait up to this many seconds for a reader before publishing (0: do not wait)")
      ->check(CLI::NonNegativeNumber);
  p->add_option("--seq-step", pub->seq_step, "header.seq advances by this per sample (gaps)")
      ->check(CLI::Range(1, 1000));
  p->callback([pub] { run_test_pub(*pub); });
}

}  // namespace poise::cli
