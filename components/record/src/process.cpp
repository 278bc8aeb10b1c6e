#include "poise/record/process.h"

#include "poise/core/attitude.h"
#include "poise/dds/convert.h"
#include "poise/ddstools/cdr.h"
#include "poise/record/idl_schema.h"
#include "poise/record/mcap.h"

#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include <fastdds/rtps/common/SerializedPayload.h>

#include <cstring>
#include <optional>

namespace poise::record {

namespace {

std::vector<uint8_t> bytes_of(const std::string& s) { return std::vector<uint8_t>(s.begin(), s.end()); }

}  // namespace

ProcessStats process_recording(const ProcessOptions& options, std::vector<ProcessFilter>& filters) {
  ProcessStats stats;
  const McapReader reader = McapReader::open_file(options.input);
  stats.input_complete = reader.report().complete;
  stats.input_problems = reader.report().problems;
  stats.corrupt_in_file = reader.report().corrupt;

  int64_t log_clock = 0;  // the writer's chunk clock: recording time, never the wall clock
  WriterOptions wopt;
  wopt.clock = [&log_clock] { return log_clock; };
  std::unique_ptr<Sink> sink;
  try {
    sink = open_file_sink(options.output);
  } catch (const IoError& e) {
    throw WriteError(e.what());
  }
  McapWriter writer(std::move(sink), wopt);

  // Input channels copied through (ids remapped), in id order: deterministic.
  std::map<uint16_t, uint16_t> schema_map;
  std::map<uint16_t, uint16_t> channel_map;
  if (options.copy_input) {
    for (const auto& [id, schema] : reader.schemas()) {
      schema_map[id] = writer.add_schema(schema.name, schema.encoding, schema.data);
    }
    for (const auto& [id, channel] : reader.channels()) {
      const uint16_t schema_id = channel.schema_id == 0 ? 0 : schema_map.at(channel.schema_id);
      channel_map[id] =
          writer.add_channel(schema_id, channel.topic, channel.message_encoding, channel.metadata);
    }
  }
  const std::string type = "poise::msg::AttitudeEstimate";
  const uint16_t estimate_schema = writer.add_schema(type, "omgidl", bytes_of(*flattened_idl(type)));
  std::vector<uint16_t> out_channels;
  std::vector<uint32_t> out_seq(filters.size(), 0);
  for (const ProcessFilter& f : filters) {
    out_channels.push_back(writer.add_channel(estimate_schema, options.output_prefix + f.name, "cdr",
                                              {{"dds_type", type},
                                               {"reliability", "RELIABLE"},
                                               {"durability", "VOLATILE"},
                                               {"qos_profile", "estimate"},
                                               {"publish_time", "header.stamp_ns"},
                                               {"produced_by", "poise process"}}));
  }

  msg::ImuSamplePubSubType imu_type;
  msg::AttitudeEstimatePubSubType estimate_type;
  msg::ImuSample imu_msg;
  msg::AttitudeEstimate estimate;
  eprosima::fastrtps::rtps::SerializedPayload_t in_payload;
  eprosima::fastrtps::rtps::SerializedPayload_t out_payload(estimate_type.m_typeSize);
  const uint64_t total = std::max<uint64_t>(1, reader.report().messages);
  int last_percent = -1;
  MessageCursor cursor = reader.messages();
  while (const MessageView* m = cursor.next()) {
    log_clock = static_cast<int64_t>(m->log_time_ns);
    ++stats.input_messages;
    if (options.progress != nullptr) {
      const int percent = static_cast<int>(100 * stats.input_messages / total);
      if (percent / 5 != last_percent / 5) {
        last_percent = percent;
        *options.progress << "poise process: " << percent << "% (" << stats.input_messages << "/"
                          << total << " messages)\n";
      }
    }
    if (options.copy_input) {
      writer.write(channel_map.at(m->channel->id), m->sequence, m->log_time_ns, m->publish_time_ns,
                   m->data, m->size);
    }
    if (m->channel->topic == options.imu_topic && m->schema != nullptr &&
        m->schema->name == "poise::msg::ImuSample") {
      ++stats.imu_samples;
      // The one payload check (bounds, encapsulation, strings, trailing bytes) before fastcdr.
      std::optional<std::string> problem = ddstools::payload_problem(
          ddstools::TypeTable::builtin(), m->schema->name, m->data, m->size);
      if (!problem) {
        in_payload.reserve(static_cast<uint32_t>(m->size));
        std::memcpy(in_payload.data, m->data, m->size);
        in_payload.length = static_cast<uint32_t>(m->size);
        try {
          if (!imu_type.deserialize(&in_payload, &imu_msg)) {
            problem = "fastcdr could not deserialize it";
          }
        } catch (const std::exception& e) {
          problem = std::string("fastcdr: ") + e.what();
        }
      }
      if (problem) {
        ++stats.undecodable;
        if (stats.undecodable_details.size() < kMaxDescribedSkips) {
          stats.undecodable_details.push_back(describe_position(*m) + " on '" + m->channel->topic +
                                              "', " + std::to_string(m->size) + " bytes: " + *problem);
        }
        continue;
      }
      const ImuSample sample = dds::from_msg(imu_msg);
      for (size_t i = 0; i < filters.size(); ++i) {
        ProcessFilter& f = filters[i];
        if (!f.filter->update(sample)) {
          ++stats.rejected[f.name];
          continue;
        }
        if (!f.filter->initialized()) {
          continue;
        }
        const Eigen::Quaterniond q = f.filter->q_world_body();
        const Eigen::Vector3d rpy = euler_zyx_from_quat(q);
        estimate = msg::AttitudeEstimate();
        estimate.header(dds::make_header(sample.stamp_ns, out_seq[i]++, "world"));
        estimate.sensor_id(imu_msg.sensor_id());
        estimate.filter_id(f.name.substr(0, 32));
        estimate.q_world_body(dds::to_msg(q));
        estimate.roll_rad(rpy.x());
        estimate.pitch_rad(rpy.y());
        estimate.yaw_rad(rpy.z());
        out_payload.length = 0;
        std::memset(out_payload.data, 0, out_payload.max_size);  // padding bytes are not written
        if (!estimate_type.serialize(&estimate, &out_payload)) {
          throw WriteError("could not serialise an AttitudeEstimate (a build defect)");
        }
        writer.write(out_channels[i], out_seq[i] - 1, m->log_time_ns,
                     static_cast<uint64_t>(sample.stamp_ns), out_payload.data, out_payload.length);
        ++stats.estimates[f.name];
      }
    }
  }
  stats.damaged_chunks = cursor.problems().size();
  for (const std::string& p : cursor.problems()) {
    stats.input_problems.push_back(p);
  }
  writer.close();
  return stats;
}

}  // namespace poise::record
