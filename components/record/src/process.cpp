#include "poise/record/process.h"

#include "poise/core/attitude.h"
#include "poise/dds/convert.h"
#include "poise/record/idl_schema.h"
#include "poise/record/mcap.h"
#include "decode.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <fastdds/rtps/common/SerializedPayload.h>

#include <algorithm>
#include <cstring>
#include <optional>
#include <variant>

namespace poise::record {

namespace {

std::vector<uint8_t> bytes_of(const std::string& s) { return std::vector<uint8_t>(s.begin(), s.end()); }

/// An attitude filter alone, as a step: quaternion and Euler angles only.
class FilterStep : public nodes::AttitudeStep {
 public:
  explicit FilterStep(ProcessFilter f)
      : AttitudeStep(f.name, f.name), filter_(std::move(f.filter)) {}
  bool step(const ImuSample& sample) override { return filter_->update(sample); }
  bool attitude(nodes::AttitudeReport& report) const override {
    if (!filter_->initialized()) {
      return false;
    }
    report.q_world_body = filter_->q_world_body();
    return true;
  }
  void diagnostics(nodes::DiagnosticsReport& /*diag*/) const override {}

 private:
  std::unique_ptr<AttitudeFilter> filter_;
};

/// One recorded input, decoded.
struct Input {
  uint64_t ordinal = 0;   ///< position of its message in the recording (0-based)
  uint64_t log_time_ns = 0;
  int64_t stamp_ns = 0;   ///< the sample stamp it is ordered by
  std::variant<msg::ImuSample, msg::VisionPose, msg::VehicleInput> sample;
};

/// One message a component produced, written after the input message that caused it.
struct Output {
  uint64_t ordinal = 0;  ///< the input message it follows
  uint16_t channel = 0;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  std::vector<uint8_t> data;
};

/// The MCAP side of StepOutputs: serialises each message onto its processed/... channel.
class McapOutputs : public nodes::StepOutputs {
 public:
  McapOutputs(McapWriter& writer, const ProcessOptions& options)
      : writer_(writer), options_(options) {}

  /// Declares the channels of a step's outputs (once per topic, in call order: deterministic).
  void declare(const nodes::EstimatorStep& step, const dds::TopicNames& topics) {
    const unsigned kinds = step.kinds();
    if ((kinds & nodes::kAttitudeOut) != 0U) {
      attitude_topics_[step.component()] =
          channel(topics.attitude(step.component()), dds::type_names::kAttitudeEstimate);
    }
    if ((kinds & nodes::kPoseOut) != 0U) {
      pose_topics_[step.component()] =
          channel(topics.pose(step.component()), dds::type_names::kPoseEstimate);
    }
    if ((kinds & nodes::kAltitudeOut) != 0U) {
      altitude_channel_ = channel(topics.altitude, dds::type_names::kAltitudeEstimate);
    }
    diagnostics_channel_ = channel(topics.diagnostics, dds::type_names::kFilterDiagnostics);
  }
  /// The input message the next outputs follow.
  void set_trigger(uint64_t ordinal, uint64_t log_time_ns) {
    ordinal_ = ordinal;
    log_time_ns_ = log_time_ns;
  }

  void attitude(const msg::AttitudeEstimate& m) override {
    put<msg::AttitudeEstimatePubSubType>(attitude_topics_.at(m.filter_id().to_string()), m);
  }
  void pose(const msg::PoseEstimate& m) override {
    put<msg::PoseEstimatePubSubType>(pose_topics_.at(m.filter_id().to_string()), m);
  }
  void altitude(const msg::AltitudeEstimate& m) override {
    put<msg::AltitudeEstimatePubSubType>(altitude_channel_, m);
  }
  void diagnostics(const msg::FilterDiagnostics& m) override {
    put<msg::FilterDiagnosticsPubSubType>(diagnostics_channel_, m);
  }

  /// The outputs in file order (after the message that caused them, in production order).
  std::vector<Output> take_sorted() {
    std::stable_sort(outputs_.begin(), outputs_.end(),
                     [](const Output& a, const Output& b) { return a.ordinal < b.ordinal; });
    return std::move(outputs_);
  }
  [[nodiscard]] const std::string& topic_of(uint16_t channel) const { return topic_names_.at(channel); }

 private:
  uint16_t channel(const std::string& live_topic, const std::string& type) {
    const std::string topic = options_.output_prefix + live_topic;
    const auto it = channels_.find(topic);
    if (it != channels_.end()) {
      return it->second;
    }
    auto schema = schemas_.find(type);
    if (schema == schemas_.end()) {
      schema = schemas_.emplace(type, writer_.add_schema(type, "omgidl", bytes_of(*flattened_idl(type)))).first;
    }
    const uint16_t id = writer_.add_channel(schema->second, topic, "cdr",
                                            {{"dds_type", type},
                                             {"reliability", "RELIABLE"},
                                             {"durability", "VOLATILE"},
                                             {"qos_profile", "estimate"},
                                             {"publish_time", "header.stamp_ns"},
                                             {"produced_by", "poise process"}});
    channels_[topic] = id;
    topic_names_[id] = topic;
    return id;
  }

  template <typename PubSubType>
  void put(uint16_t channel, const typename PubSubType::type& m) {
    PubSubType type;
    eprosima::fastrtps::rtps::SerializedPayload_t payload(type.getSerializedSizeProvider(
        const_cast<typename PubSubType::type*>(&m))());
    std::memset(payload.data, 0, payload.max_size);  // padding bytes are not written
    if (!type.serialize(const_cast<typename PubSubType::type*>(&m), &payload)) {
      throw WriteError("could not serialise a " + std::string(type.getName()) + " (a build defect)");
    }
    Output out;
    out.ordinal = ordinal_;
    out.channel = channel;
    out.log_time_ns = log_time_ns_;
    out.publish_time_ns = static_cast<uint64_t>(std::max<int64_t>(0, m.header().stamp_ns()));
    out.data.assign(payload.data, payload.data + payload.length);
    outputs_.push_back(std::move(out));
  }

  McapWriter& writer_;
  const ProcessOptions& options_;
  std::map<std::string, uint16_t> schemas_;
  std::map<std::string, uint16_t> channels_;
  std::map<uint16_t, std::string> topic_names_;
  std::map<std::string, uint16_t> attitude_topics_;  // by filter id
  std::map<std::string, uint16_t> pose_topics_;      // by filter id
  uint16_t altitude_channel_ = 0;
  uint16_t diagnostics_channel_ = 0;
  uint64_t ordinal_ = 0;
  uint64_t log_time_ns_ = 0;
  std::vector<Output> outputs_;
};

}  // namespace

std::unique_ptr<nodes::EstimatorStep> filter_step(ProcessFilter filter) {
  return std::make_unique<FilterStep>(std::move(filter));
}

ProcessStats process_recording(const ProcessOptions& options, std::vector<ProcessFilter>& filters) {
  std::vector<ProcessComponent> components;
  for (ProcessFilter& f : filters) {
    components.push_back({filter_step(std::move(f)), nodes::NodeParams{}});
  }
  filters.clear();
  return process_recording(options, components);
}

ProcessStats process_recording(const ProcessOptions& options, std::vector<ProcessComponent>& components) {
  ProcessStats stats;
  const McapReader reader = McapReader::open_file(options.input);
  stats.input_complete = reader.report().complete;
  stats.input_problems = reader.report().problems;
  stats.corrupt_in_file = reader.report().corrupt;

  bool wants_vision = false;
  bool wants_vehicle = false;
  for (const ProcessComponent& c : components) {
    wants_vision = wants_vision || c.step->uses_vision();
    wants_vehicle = wants_vehicle || c.step->uses_vehicle_input();
  }

  // Pass 1: decode the inputs (malformed payloads are counted and named, never processed).
  const uint64_t total = std::max<uint64_t>(1, reader.report().messages);
  const auto progress = [&options, total](uint64_t phase, uint64_t done) {
    if (options.progress) {
      options.progress(phase * total + done, 3 * total);  // decode, run, write
    }
  };
  std::vector<Input> inputs;
  uint64_t malformed_imu = 0;
  uint64_t malformed_vision = 0;
  uint64_t malformed_vehicle = 0;
  {
    MessageCursor cursor = reader.messages();
    uint64_t ordinal = 0;
    while (const MessageView* m = cursor.next()) {
      const uint64_t index = ordinal++;
      ++stats.input_messages;
      progress(0, stats.input_messages);
      if (m->schema == nullptr) {
        continue;
      }
      const std::string& topic = m->channel->topic;
      const std::string& type = m->schema->name;
      Input in;
      in.ordinal = index;
      in.log_time_ns = m->log_time_ns;
      std::optional<std::string> problem;
      uint64_t* malformed = nullptr;
      if (topic == options.topics.imu && type == dds::type_names::kImuSample) {
        ++stats.imu_samples;
        msg::ImuSample s;
        problem = decode<msg::ImuSamplePubSubType>(*m, s);
        in.stamp_ns = s.header().stamp_ns();
        in.sample = std::move(s);
        malformed = &malformed_imu;
      } else if (wants_vision && topic == options.topics.vision_pose &&
                 type == dds::type_names::kVisionPose) {
        ++stats.vision_samples;
        msg::VisionPose s;
        problem = decode<msg::VisionPosePubSubType>(*m, s);
        in.stamp_ns = s.capture_stamp_ns();
        in.sample = std::move(s);
        malformed = &malformed_vision;
      } else if (wants_vehicle && topic == options.topics.vehicle_input &&
                 type == dds::type_names::kVehicleInput) {
        ++stats.vehicle_inputs;
        msg::VehicleInput s;
        problem = decode<msg::VehicleInputPubSubType>(*m, s);
        in.stamp_ns = s.header().stamp_ns();
        in.sample = std::move(s);
        malformed = &malformed_vehicle;
      } else {
        continue;
      }
      if (problem) {
        ++*malformed;
        ++stats.undecodable;
        if (stats.undecodable_details.size() < kMaxDescribedSkips) {
          stats.undecodable_details.push_back(describe_position(*m) + " on '" + topic + "', " +
                                              std::to_string(m->size) + " bytes: " + *problem);
        }
        continue;
      }
      inputs.push_back(std::move(in));
    }
    stats.damaged_chunks = cursor.problems().size();
    for (const std::string& p : cursor.problems()) {
      stats.input_problems.push_back(p);
    }
  }
  if (options.order == ProcessOrder::kStamp) {
    std::stable_sort(inputs.begin(), inputs.end(),
                     [](const Input& a, const Input& b) { return a.stamp_ns < b.stamp_ns; });
  }
  {  // samples the recording lacks (lost before the recorder): said, since live had them
    std::map<std::string, uint32_t> last_seq;
    for (const Input& in : inputs) {
      if (const auto* imu = std::get_if<msg::ImuSample>(&in.sample)) {
        const uint32_t seq = imu->header().seq();
        const auto [it, first] = last_seq.try_emplace(imu->sensor_id().to_string(), seq);
        if (!first && seq - it->second > 1U && seq - it->second < (1U << 31)) {
          ++stats.imu_gaps;
          stats.imu_missing += seq - it->second - 1U;
        }
        it->second = seq;
      }
    }
  }

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

  // The components, each in the node's shape; time = the stamp of the input being processed.
  McapOutputs outputs(writer, options);
  int64_t now_ns = inputs.empty() ? 0 : inputs.front().stamp_ns;
  std::vector<std::unique_ptr<nodes::StepRunner>> runners;
  for (ProcessComponent& c : components) {
    outputs.declare(*c.step, options.topics);
    auto runner = std::make_unique<nodes::StepRunner>(std::move(c.step), c.params, options.topics,
                                                      [&now_ns] { return now_ns; });
    runner->imu_malformed().store(malformed_imu);
    runner->vision_malformed().store(malformed_vision);
    runner->vehicle_input_malformed().store(malformed_vehicle);
    runners.push_back(std::move(runner));
  }
  components.clear();

  const std::string writer_id = "recording";  // one publisher per input: no restarts offline
  uint64_t ran = 0;
  for (const Input& in : inputs) {
    progress(1, ++ran);
    now_ns = in.stamp_ns;
    outputs.set_trigger(in.ordinal, in.log_time_ns);
    if (const auto* imu = std::get_if<msg::ImuSample>(&in.sample)) {
      const ImuSample sample = dds::from_msg(*imu);
      const std::string source = imu->sensor_id().to_string();
      for (auto& r : runners) {
        r->imu(sample, source, writer_id, outputs);
      }
    } else if (const auto* vision = std::get_if<msg::VisionPose>(&in.sample)) {
      for (auto& r : runners) {
        r->vision(*vision, writer_id);
      }
    } else if (const auto* vehicle = std::get_if<msg::VehicleInput>(&in.sample)) {
      for (auto& r : runners) {
        r->vehicle_input(*vehicle, writer_id);
      }
    }
  }
  inputs.clear();
  inputs.shrink_to_fit();
  for (const auto& r : runners) {
    const std::string& name = r->step().sensor_id();
    stats.estimates[name] += r->published();
    stats.rejected[name] += r->rejected();
    stats.diagnostics[name] += r->diagnostics_published();
  }

  // Pass 2: the input copied through, each output right after the message that caused it.
  const std::vector<Output> produced = outputs.take_sorted();
  std::map<uint16_t, uint32_t> out_seq;
  size_t next = 0;
  auto write_outputs_until = [&](uint64_t ordinal) {
    for (; next < produced.size() && produced[next].ordinal <= ordinal; ++next) {
      const Output& o = produced[next];
      log_clock = static_cast<int64_t>(o.log_time_ns);
      writer.write(o.channel, out_seq[o.channel]++, o.log_time_ns, o.publish_time_ns, o.data.data(),
                   o.data.size());
      ++stats.per_topic[outputs.topic_of(o.channel)];
    }
  };
  {
    MessageCursor cursor = reader.messages();
    uint64_t ordinal = 0;
    while (const MessageView* m = cursor.next()) {
      const uint64_t index = ordinal++;
      progress(2, ordinal);
      log_clock = static_cast<int64_t>(m->log_time_ns);
      if (options.copy_input) {
        writer.write(channel_map.at(m->channel->id), m->sequence, m->log_time_ns, m->publish_time_ns,
                     m->data, m->size);
      }
      write_outputs_until(index);
    }
    write_outputs_until(UINT64_MAX);
  }
  writer.close();
  return stats;
}

}  // namespace poise::record
