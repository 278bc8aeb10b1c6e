#include "poise/record/recorder.h"

#include "poise/dds/participant.h"
#include "poise/dds/topics.h"
#include "poise/record/idl_schema.h"
#include "poise/schema/cdr.h"
#include "poise/schema/raw_type.h"

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/rtps/writer/WriterDiscoveryInfo.h>
#include <fastrtps/rtps/builtin/data/WriterProxyData.h>

#include <chrono>
#include <condition_variable>
#include <algorithm>
#include <deque>
#include <iostream>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>

namespace poise::record {

namespace fdds = eprosima::fastdds::dds;
using eprosima::fastrtps::types::ReturnCode_t;

std::string split_file_name(const std::string& output, int index) {
  std::string stem = output;
  if (stem.size() > 5 && stem.compare(stem.size() - 5, 5, ".mcap") == 0) {
    stem.resize(stem.size() - 5);
  }
  char suffix[16];
  std::snprintf(suffix, sizeof(suffix), "_%03d.mcap", index);
  return stem + suffix;
}

namespace {

int64_t realtime_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

const char* reliability_name(fdds::ReliabilityQosPolicyKind kind) {
  return kind == fdds::RELIABLE_RELIABILITY_QOS ? "RELIABLE" : "BEST_EFFORT";
}

const char* durability_name(fdds::DurabilityQosPolicyKind kind) {
  switch (kind) {
    case fdds::VOLATILE_DURABILITY_QOS: return "VOLATILE";
    case fdds::TRANSIENT_LOCAL_DURABILITY_QOS: return "TRANSIENT_LOCAL";
    case fdds::TRANSIENT_DURABILITY_QOS: return "TRANSIENT";
    case fdds::PERSISTENT_DURABILITY_QOS: return "PERSISTENT";
  }
  return "VOLATILE";
}

}  // namespace

struct Recorder::Impl : public fdds::DomainParticipantListener {
  struct Discovered {
    std::string topic;
    std::string type;
    fdds::ReliabilityQosPolicyKind reliability;
    fdds::DurabilityQosPolicyKind durability;
  };
  struct Pending {
    size_t sub;
    uint32_t sequence;
    int64_t log_ns;
    int64_t publish_ns;
    std::vector<uint8_t> bytes;
  };
  struct Sub;
  class SubListener : public fdds::DataReaderListener {
   public:
    SubListener(Impl* impl, size_t index, std::string type)
        : impl_(impl),
          index_(index),
          type_(std::move(type)),
          poise_stamp_(schema::has_header_stamp(schema::TypeTable::builtin(), type_)),
          ros_stamp_(schema::has_ros_header_stamp(schema::TypeTable::builtin(), type_)) {}
    void on_data_available(fdds::DataReader* reader) override {
      dds::RawSample sample;
      fdds::SampleInfo info;
      while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) {
          continue;
        }
        const std::optional<std::string> problem = schema::payload_problem(
            schema::TypeTable::builtin(), type_, sample.data.data(), sample.data.size());
        const uint64_t seq = info.sample_identity.sequence_number().to64long();
        if (problem) {
          impl_->reject(index_, sample.data.size(), info.sample_identity.writer_guid(), seq,
                        *problem);
          continue;
        }
        Pending p;
        p.sub = index_;
        p.log_ns = impl_->log_now();
        p.sequence = static_cast<uint32_t>(seq & 0xFFFFFFFFu);
        // publish_time: the header stamp of poise types and of ROS 2 types, else the source time.
        const std::optional<int64_t> stamp =
            ros_stamp_ ? schema::read_ros_header_stamp_ns(sample.data.data(), sample.data.size())
            : poise_stamp_ ? schema::read_header_stamp_ns(sample.data.data(), sample.data.size())
                           : std::nullopt;
        p.publish_ns = stamp && *stamp > 0 ? *stamp : info.source_timestamp.to_ns();
        p.bytes = std::move(sample.data);
        impl_->push(std::move(p), info.sample_identity.writer_guid(), seq);
      }
    }

    void on_subscription_matched(fdds::DataReader* /*reader*/,
                                 const fdds::SubscriptionMatchedStatus& info) override {
      impl_->owner.matched_.fetch_add(info.current_count_change);
    }

   private:
    Impl* impl_;
    size_t index_;
    std::string type_;
    bool poise_stamp_;  // header.stamp_ns (poise types)
    bool ros_stamp_;    // header.stamp {sec, nanosec} (ROS 2 types, idl/ros2)
  };
  struct Sub {
    std::string topic;
    std::string type;
    std::string schema_text;
    std::map<std::string, std::string> metadata;
    uint16_t channel = 0;  // in the current file
    fdds::Topic* dds_topic = nullptr;
    fdds::DataReader* reader = nullptr;
    std::unique_ptr<SubListener> listener;
  };

  Recorder& owner;
  RecorderOptions& opt;
  std::ostream& log;
  fdds::DomainParticipant* participant = nullptr;
  fdds::Subscriber* subscriber = nullptr;

  std::mutex mutex;
  std::condition_variable cv;
  std::deque<Discovered> discovered;
  std::deque<Pending> queue;
  std::map<std::pair<eprosima::fastrtps::rtps::GUID_t, size_t>, uint64_t> last_seq;
  RecorderStats stats;  // received/gaps/dropped under mutex

  std::vector<std::unique_ptr<Sub>> subs;  // main thread only (listeners hold indices)
  std::map<std::string, size_t> by_topic;
  std::set<std::string> warned;
  std::unique_ptr<McapWriter> writer;
  std::map<std::string, uint16_t> schema_ids;  // current file
  int file_index = 0;

  Impl(Recorder& o, RecorderOptions& options)
      : owner(o), opt(options), log(options.log != nullptr ? *options.log : std::cerr) {}

  int64_t log_now() const { return opt.log_clock ? opt.log_clock() : realtime_ns(); }

  void on_publisher_discovery(fdds::DomainParticipant* /*participant*/,
                              eprosima::fastrtps::rtps::WriterDiscoveryInfo&& info) override {
    if (info.status != eprosima::fastrtps::rtps::WriterDiscoveryInfo::DISCOVERED_WRITER) {
      return;
    }
    Discovered d;
    d.topic = info.info.topicName().to_string();
    d.type = info.info.typeName().to_string();
    d.reliability = info.info.m_qos.m_reliability.kind;
    d.durability = info.info.m_qos.m_durability.kind;
    std::lock_guard<std::mutex> lock(mutex);
    discovered.push_back(std::move(d));
    cv.notify_one();
  }

  // Per writer and topic, from DDS sequence numbers (1 for a writer's first sample): the
  // writer's first sample to reach us says how many it wrote before the match (a recorder that
  // matches a running writer late never sees them: they are in no gap), a later jump is a gap.
  // Caller holds the mutex; malformed samples count too (they were received).
  void track_sequence(TopicStats& t, size_t sub, const eprosima::fastrtps::rtps::GUID_t& writer_guid,
                      uint64_t seq) {
    ++t.received;
    ++stats.received;
    uint64_t& last = last_seq[{writer_guid, sub}];
    if (last == 0 && seq > 1) {
      t.before_match += seq - 1;
      stats.before_match += seq - 1;
    } else if (last != 0 && seq > last + 1) {
      t.gaps += seq - last - 1;
      stats.sequence_gaps += seq - last - 1;
    }
    last = std::max(last, seq);
  }

  void push(Pending&& p, const eprosima::fastrtps::rtps::GUID_t& writer_guid, uint64_t seq) {
    std::lock_guard<std::mutex> lock(mutex);
    TopicStats& t = stats.topics[subs_topic_name(p.sub)];
    track_sequence(t, p.sub, writer_guid, seq);
    if (queue.size() >= opt.max_queue_messages) {
      ++stats.dropped_queue_full;
      ++t.dropped;
      return;
    }
    queue.push_back(std::move(p));
    cv.notify_one();
  }

  // A malformed payload (listener thread): counted; its reason is kept for the report.
  void reject(size_t sub, size_t bytes, const eprosima::fastrtps::rtps::GUID_t& writer_guid,
              uint64_t seq, const std::string& problem) {
    std::lock_guard<std::mutex> lock(mutex);
    TopicStats& t = stats.topics[subs_topic_name(sub)];
    track_sequence(t, sub, writer_guid, seq);
    ++t.malformed;
    ++stats.malformed;
    if (t.first_problem.empty()) {
      std::ostringstream from;
      from << writer_guid;
      t.first_problem = std::to_string(bytes) + " bytes from writer " + from.str() + ": " + problem;
    }
  }

  // Reports topics whose malformed count grew since the last call (main thread).
  std::map<std::string, uint64_t> malformed_reported;
  void report_malformed() {
    std::vector<std::pair<std::string, TopicStats>> grown;
    {
      std::lock_guard<std::mutex> lock(mutex);
      for (const auto& [topic, t] : stats.topics) {
        if (t.malformed > malformed_reported[topic]) {
          malformed_reported[topic] = t.malformed;
          grown.emplace_back(topic, t);
        }
      }
    }
    for (const auto& [topic, t] : grown) {
      log << "poise record: '" << topic << "': " << t.malformed
          << " malformed payload(s) rejected so far, not recorded (first: " << t.first_problem
          << ")\n";
    }
  }

  // Topic names are copied at subscription time so listener threads never touch `subs`.
  std::vector<std::string> topic_names;  // guarded by mutex
  const std::string& subs_topic_name(size_t index) const { return topic_names[index]; }

  void warn_once(const std::string& key, const std::string& text) {
    if (warned.insert(key).second) {
      log << "poise record: " << text << "\n";
    }
  }

  void create_participant() {
    dds::ParticipantOptions popt;
    popt.domain = opt.domain;
    popt.profile = opt.participant_profile;
    popt.name = "poise record";
    popt.role = dds::ParticipantRole::kObserver;  // records every topic, also via a server
    participant = dds::create_participant(popt, this, fdds::StatusMask::none());
    subscriber = participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
    if (subscriber == nullptr) {
      throw dds::DdsError("cannot create a DDS subscriber");
    }
  }

  void destroy_participant() {
    if (participant == nullptr) {
      return;
    }
    participant->set_listener(nullptr);
    participant->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(participant);
    participant = nullptr;
  }

  std::string current_path() const {
    return opt.split_size_bytes > 0 ? split_file_name(opt.output, file_index) : opt.output;
  }

  void register_channel(Sub& s) {
    auto found = schema_ids.find(s.type);
    if (found == schema_ids.end()) {
      const uint16_t id = writer->add_schema(
          s.type, "omgidl", std::vector<uint8_t>(s.schema_text.begin(), s.schema_text.end()));
      found = schema_ids.emplace(s.type, id).first;
    }
    s.channel = writer->add_channel(found->second, s.topic, "cdr", s.metadata);
  }

  void open_file() {
    const std::string path = current_path();
    try {
      writer = std::make_unique<McapWriter>(open_file_sink(path), opt.writer);
    } catch (const IoError& e) {
      throw WriteError(e.what());
    }
    accounted = false;
    schema_ids.clear();
    stats.files.push_back(path);
    for (auto& s : subs) {
      register_channel(*s);
    }
  }

  void subscribe(const Discovered& d) {
    const bool wanted = opt.all || std::find(opt.topics.begin(), opt.topics.end(), d.topic) !=
                                       opt.topics.end();
    if (!wanted) {
      return;
    }
    const auto existing = by_topic.find(d.topic);
    if (existing != by_topic.end()) {
      if (subs[existing->second]->type != d.type) {
        warn_once("type:" + d.topic + d.type,
                  "topic '" + d.topic + "' is also published with type " + d.type +
                      "; recording only " + subs[existing->second]->type);
      }
      return;
    }
    const std::optional<std::string> idl = flattened_idl(d.type);
    if (!idl) {
      if (opt.all && !d.topic.empty() && d.topic[0] == '_') {
        return;  // middleware-internal topics (e.g. Fast DDS statistics): not user data
      }
      warn_once("unknown:" + d.topic,
                "topic '" + d.topic + "' has type " + d.type +
                    " which is neither a poise nor a ROS 2 IDL type (idl/, idl/ros2/): not recorded");
      return;
    }
    auto s = std::make_unique<Sub>();
    s->topic = d.topic;
    s->type = d.type;
    s->schema_text = *idl;
    const dds::QosKind kind = dds::default_qos_for_topic(d.topic);
    s->metadata = {{"dds_type", d.type},
                   {"reliability", reliability_name(d.reliability)},
                   {"durability", durability_name(d.durability)},
                   {"qos_profile", dds::profile_name(kind)},
                   {"publish_time", schema::has_ros_header_stamp(schema::TypeTable::builtin(), d.type)
                                        ? "header.stamp"
                                        : schema::has_header_stamp(schema::TypeTable::builtin(), d.type)
                                              ? "header.stamp_ns"
                                              : "source_timestamp"}};
    fdds::TypeSupport type(new dds::RawPubSubType(d.type, &schema::TypeTable::builtin()));
    if (participant->find_type(d.type).empty() &&
        type.register_type(participant) != ReturnCode_t::RETCODE_OK) {
      throw dds::DdsError("cannot register the raw type " + d.type);
    }
    s->dds_topic = participant->create_topic(d.topic, d.type, fdds::TOPIC_QOS_DEFAULT);
    if (s->dds_topic == nullptr) {
      throw dds::DdsError("cannot create topic '" + d.topic + "'");
    }
    fdds::DataReaderQos qos = subscriber->get_default_datareader_qos();
    subscriber->get_datareader_qos_from_profile(dds::profile_name(kind), qos);
    // Match the discovered writer: a reliable reader does not match a best-effort writer, and a
    // transient-local reader gets the writer's history.
    qos.reliability().kind = d.reliability == fdds::RELIABLE_RELIABILITY_QOS
                                 ? fdds::RELIABLE_RELIABILITY_QOS
                                 : fdds::BEST_EFFORT_RELIABILITY_QOS;
    qos.durability().kind = (d.durability == fdds::TRANSIENT_LOCAL_DURABILITY_QOS &&
                             d.reliability == fdds::RELIABLE_RELIABILITY_QOS)
                                ? fdds::TRANSIENT_LOCAL_DURABILITY_QOS
                                : fdds::VOLATILE_DURABILITY_QOS;
    const size_t index = subs.size();
    {
      std::lock_guard<std::mutex> lock(mutex);
      topic_names.push_back(d.topic);
      stats.topics[d.topic].type = d.type;
    }
    s->listener = std::make_unique<SubListener>(this, index, d.type);
    register_channel(*s);
    subs.push_back(std::move(s));
    by_topic[d.topic] = index;
    Sub& sub = *subs.back();
    sub.reader = subscriber->create_datareader(
        sub.dds_topic, qos, sub.listener.get(),
        fdds::StatusMask::data_available() << fdds::StatusMask::subscription_matched());
    if (sub.reader == nullptr) {
      throw dds::DdsError("cannot create a reader on '" + d.topic + "'");
    }
    owner.subscribed_.fetch_add(1);
    log << "poise record: recording '" << d.topic << "' (" << d.type << ", "
        << reliability_name(d.reliability) << ")\n";
  }

  void write_pending(Pending& p) {
    Sub& s = *subs[p.sub];
    writer->write(s.channel, p.sequence, static_cast<uint64_t>(p.log_ns),
                  static_cast<uint64_t>(std::max<int64_t>(0, p.publish_ns)), p.bytes.data(),
                  p.bytes.size());
    owner.written_.fetch_add(1);
  }

  // Adds what the current file holds (durable chunks, per channel) to the written counts; once
  // per file, after it was closed or failed.
  bool accounted = false;
  void account_file() {
    if (accounted || !writer) {
      return;
    }
    accounted = true;
    const auto& held = writer->channel_messages();
    std::lock_guard<std::mutex> lock(mutex);
    for (const auto& sub : subs) {
      const auto it = held.find(sub->channel);
      const uint64_t n = it == held.end() ? 0 : it->second;
      stats.topics[sub->topic].written += n;
      stats.written += n;
    }
  }

  // After the participant is gone: every valid sample received and not in the file is lost.
  void account_lost() {
    std::lock_guard<std::mutex> lock(mutex);
    for (auto& [topic, t] : stats.topics) {
      (void)topic;
      const uint64_t kept = t.written + t.malformed + t.dropped;
      t.lost = t.received > kept ? t.received - kept : 0;
    }
    const uint64_t kept = stats.written + stats.malformed + stats.dropped_queue_full;
    stats.lost = stats.received > kept ? stats.received - kept : 0;
  }
};

Recorder::Recorder(RecorderOptions options) : options_(std::move(options)) {
  if (options_.output.empty()) {
    throw WriteError("no output file given (-o FILE.mcap)");
  }
  if (!options_.all && options_.topics.empty()) {
    throw WriteError("no topics given: name the topics to record or use --all");
  }
  impl_ = std::make_unique<Impl>(*this, options_);
}

Recorder::~Recorder() {
  if (impl_) {
    impl_->destroy_participant();
  }
}

RecorderStats Recorder::run() {
  Impl& im = *impl_;
  const auto t0 = std::chrono::steady_clock::now();
  im.open_file();
  im.create_participant();
  auto last_progress = t0;
  std::deque<Impl::Pending> batch;
  std::deque<Impl::Discovered> found;
  auto stop_now = [&] {
    if (stop_.load() || (options_.should_stop && options_.should_stop())) {
      return true;
    }
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return options_.duration_s > 0.0 && elapsed >= options_.duration_s;
  };
  auto drain = [&]() {
    for (auto& d : found) {
      im.subscribe(d);
    }
    found.clear();
    for (auto& p : batch) {
      im.write_pending(p);
      if (options_.split_size_bytes > 0 &&
          im.writer->stats().bytes + im.writer->stats().pending_messages * 64 >=
              options_.split_size_bytes) {
        im.writer->close();
        im.account_file();
        ++im.file_index;
        im.open_file();
      }
    }
    batch.clear();
    im.writer->tick();
  };
  try {
    while (!stop_now()) {
      {
        std::unique_lock<std::mutex> lock(im.mutex);
        im.cv.wait_for(lock, std::chrono::milliseconds(100),
                       [&] { return !im.queue.empty() || !im.discovered.empty(); });
        batch.swap(im.queue);
        found.swap(im.discovered);
      }
      drain();
      const auto now = std::chrono::steady_clock::now();
      if (now - last_progress >= std::chrono::seconds(5)) {
        last_progress = now;
        im.report_malformed();
        uint64_t malformed = 0;
        {
          std::lock_guard<std::mutex> lock(im.mutex);
          malformed = im.stats.malformed;
        }
        im.log << "poise record: " << written_.load() << " messages on " << subscribed_.load()
               << " topics, " << im.writer->stats().bytes / 1024 << " KiB in "
               << im.current_path() << ", " << malformed << " malformed rejected\n";
        std::string waiting;
        for (const std::string& t : options_.all ? std::vector<std::string>{} : options_.topics) {
          if (im.by_topic.count(t) == 0) {
            waiting += " " + t;
          }
        }
        if (!waiting.empty()) {
          im.log << "poise record: no publisher discovered yet on:" << waiting
                 << " (check the topic names and --domain)\n";
        }
      }
    }
    // Stop receiving, then write what is queued.
    for (auto& s : im.subs) {
      if (s->reader != nullptr) {
        s->reader->set_listener(nullptr);
      }
    }
    {
      std::lock_guard<std::mutex> lock(im.mutex);
      batch.swap(im.queue);
      found.clear();
      im.discovered.clear();
    }
    drain();
    im.writer->close();
  } catch (const WriteError& e) {
    std::lock_guard<std::mutex> lock(im.mutex);
    im.stats.error = e.what();
  }
  im.account_file();  // the writer is closed, or failed with its durable chunks finalised
  im.destroy_participant();
  im.account_lost();
  std::lock_guard<std::mutex> lock(im.mutex);
  if (!im.stats.error.empty() && im.writer && !im.writer->failure_detail().empty()) {
    // The writer knew what was lost when it failed; the recorder's count adds the queue and what
    // arrived until it unsubscribed: the error line says the same number as the table (issue 33).
    im.stats.error = im.writer->failure_detail() + " (" + std::to_string(im.stats.lost) + " messages lost)";
  }
  im.stats.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return im.stats;
}

}  // namespace poise::record
