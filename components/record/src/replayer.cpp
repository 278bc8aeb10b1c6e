#include "poise/record/replayer.h"

#include "poise/dds/participant.h"
#include "poise/dds/topics.h"
#include "poise/schema/cdr.h"
#include "poise/schema/raw_type.h"

#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>

#include <chrono>
#include <iostream>
#include <optional>
#include <set>
#include <thread>

namespace poise::record {

namespace fdds = eprosima::fastdds::dds;

namespace {

dds::QosKind kind_from(const Channel& channel) {
  const auto p = channel.metadata.find("qos_profile");
  if (p != channel.metadata.end()) {
    for (dds::QosKind k : {dds::QosKind::kSensor, dds::QosKind::kEstimate, dds::QosKind::kStatic}) {
      if (p->second == dds::profile_name(k)) {
        return k;
      }
    }
  }
  return dds::default_qos_for_topic(channel.topic);
}

std::string meta(const Channel& channel, const std::string& key) {
  const auto it = channel.metadata.find(key);
  return it == channel.metadata.end() ? std::string() : it->second;
}

struct Output {
  fdds::DataWriter* writer = nullptr;
  std::unique_ptr<dds::detail::MatchCounter> matches;
  dds::RawSample sample;
  std::string type_name;  // checked against the built-in IDL when it knows the type
};

}  // namespace

// not split: one replay's lifecycle (open, writers per channel, match wait, schedule, drain) whose
// steps share the participant and the writers.
ReplayStats replay(const ReplayOptions& options) {
  std::ostream& log = options.log != nullptr ? *options.log : std::cerr;
  McapReader reader = McapReader::open_file(options.input);
  ReplayStats stats;
  stats.complete = reader.report().complete;
  stats.file_problems = reader.report().problems;
  stats.corrupt_in_file = reader.report().corrupt;
  if (!stats.complete) {
    log << "poise replay: " << options.input
        << " is incomplete; replaying what could be recovered (" << reader.report().messages
        << " messages):\n";
    for (const std::string& p : reader.report().problems) {
      log << "  " << p << "\n";
    }
  }
  dds::Participant participant(
      {options.domain, options.participant_profile, "", "poise replay"});
  // One DDS writer per channel that carries messages, made before the replay for the channels the
  // file's counts name and on the first message for the rest; never more than max_writers (a
  // writer costs ~90 KB: a file declaring 65535 channels must not cost gigabytes).
  std::map<uint16_t, std::optional<Output>> outputs;
  std::set<uint16_t> over_limit;
  const auto make_output = [&](const Channel& channel) -> std::optional<Output> {
    if (!options.schedule.topics.empty() && options.schedule.topics.count(channel.topic) == 0) {
      return std::nullopt;
    }
    const auto schema = reader.schemas().find(channel.schema_id);
    const std::string type_name =
        schema != reader.schemas().end() ? schema->second.name : meta(channel, "dds_type");
    if (type_name.empty() || channel.message_encoding != "cdr") {
      log << "poise replay: skipping '" << channel.topic << "' (no DDS type or not CDR)\n";
      return std::nullopt;
    }
    if (stats.writers >= options.max_writers) {
      over_limit.insert(channel.id);
      if (++stats.channels_over_limit <= kMaxDescribedSkips) {
        log << "poise replay: skipping '" << channel.topic << "' (channel " << channel.id << "): more than "
            << options.max_writers << " topics carry messages\n";
      }
      return std::nullopt;
    }
    const schema::TypeTable& table = schema::TypeTable::builtin();
    if (table.find_struct(type_name) == nullptr) {
      log << "poise replay: '" << channel.topic << "' has type " << type_name
          << " unknown to this build: published unkeyed\n";
    }
    fdds::Topic* topic = participant.topic(
        channel.topic, fdds::TypeSupport(new dds::RawPubSubType(type_name, &table)));
    const dds::QosKind kind = kind_from(channel);
    fdds::DataWriterQos qos = participant.publisher()->get_default_datawriter_qos();
    participant.publisher()->get_datawriter_qos_from_profile(dds::profile_name(kind), qos);
    if (meta(channel, "reliability") == "RELIABLE") {
      qos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
    } else if (meta(channel, "reliability") == "BEST_EFFORT") {
      qos.reliability().kind = fdds::BEST_EFFORT_RELIABILITY_QOS;
    }
    if (qos.reliability().kind == fdds::RELIABLE_RELIABILITY_QOS) {
      // Reliable topics are replayed without loss: a slow reader slows the replay down.
      qos.history().kind = fdds::KEEP_ALL_HISTORY_QOS;
      // One instance per sensor_id, as many as the QoS profiles keep (a fleet's recording holds
      // one per robot: 8 here refused every sample of the 9th robot on), each holding up to 512
      // unacknowledged samples; Fast DDS requires the total to cover instances x per instance
      // (history memory grows on demand: the bound is reached only by that many stalled robots).
      constexpr int32_t kInstances = 256;
      constexpr int32_t kPerInstance = 512;
      qos.resource_limits().max_instances = kInstances;
      qos.resource_limits().max_samples_per_instance = kPerInstance;
      qos.resource_limits().max_samples = kInstances * kPerInstance;
      qos.reliability().max_blocking_time = eprosima::fastrtps::Duration_t(5, 0);
    }
    if (meta(channel, "durability") == "TRANSIENT_LOCAL") {
      qos.durability().kind = fdds::TRANSIENT_LOCAL_DURABILITY_QOS;
    }
    Output out;
    out.type_name = type_name;
    out.matches = std::make_unique<dds::detail::MatchCounter>();
    out.writer = participant.publisher()->create_datawriter(
        topic, qos, out.matches.get(), fdds::StatusMask::publication_matched());
    if (out.writer == nullptr) {
      throw dds::DdsError("cannot create a DDS writer on '" + channel.topic + "'");
    }
    ++stats.writers;
    return out;
  };
  const auto output_for = [&](const Channel& channel) -> Output* {
    auto it = outputs.find(channel.id);
    if (it == outputs.end()) {
      it = outputs.emplace(channel.id, make_output(channel)).first;
    }
    return it->second ? &*it->second : nullptr;
  };
  bool any = false;
  for (const auto& [id, channel] : reader.channels()) {
    const auto counted = reader.report().channels.find(id);
    if (counted != reader.report().channels.end() && counted->second.messages > 0) {
      any = output_for(channel) != nullptr || any;
    }
  }
  if (!any && reader.report().messages > 0 && !reader.report().channels.empty()) {
    log << "poise replay: no topic selected\n";
    return stats;
  }
  // Give subscribers a bounded chance to match before the first sample.
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(options.wait_for_subscribers_s));
  while (std::chrono::steady_clock::now() < deadline) {
    bool all = true;
    for (const auto& [id, out] : outputs) {
      all = all && (!out || out->matches->matched() > 0);
    }
    if (all || (options.schedule.should_stop && options.schedule.should_stop())) {
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ScheduleOptions schedule = options.schedule;
  stats.schedule = run_schedule(reader, schedule, options.clock, [&](const MessageView& m) {
    Output* const found = output_for(*m.channel);
    if (found == nullptr) {
      if (over_limit.count(m.channel->id) > 0) {
        ++stats.over_limit_messages;  // counted; topics not selected or not CDR are said above
      }
      return false;
    }
    Output& out = *found;
    const std::optional<std::string> problem = schema::payload_problem(
        schema::TypeTable::builtin(), out.type_name, m.data, m.size);
    if (problem) {
      if (++stats.malformed <= kMaxDescribedSkips) {
        log << "poise replay: skipped " << describe_position(m) << " on '" << m.channel->topic
            << "', " << m.size << " bytes: " << *problem << "\n";
      }
      return false;
    }
    out.sample.data.assign(m.data, m.data + m.size);
    if (!out.writer->write(&out.sample)) {
      ++stats.write_failures;
      return false;
    }
    return true;
  });
  for (const std::string& p : stats.schedule.problems) {
    log << "poise replay: " << p << "\n";
  }
  // Let reliable writers deliver what they hold before the participant goes away.
  for (auto& [id, out] : outputs) {
    if (out) {
      out->writer->wait_for_acknowledgments(eprosima::fastrtps::Duration_t(2, 0));
      out->writer->set_listener(nullptr);
    }
  }
  return stats;
}

}  // namespace poise::record
