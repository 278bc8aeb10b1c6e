#include "poise/process/process.h"

#include "poise/core/attitude.h"
#include "poise/dds/convert.h"
#include "poise/nodes/reports.h"
#include "poise/record/idl_schema.h"
#include "poise/record/mcap.h"
#include "decode.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/sensor_infoPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <fastdds/rtps/common/SerializedPayload.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstring>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <queue>
#include <set>
#include <tuple>
#include <utility>
#include <variant>

namespace poise::record {

namespace {

std::vector<uint8_t> bytes_of(const std::string& s) { return std::vector<uint8_t>(s.begin(), s.end()); }

/// An attitude filter alone, as a step: quaternion, Euler angles and the covariance it publishes
/// (REP 145's -1 in the first element when it has none).
class FilterStep : public nodes::AttitudeStep {
 public:
  explicit FilterStep(ProcessFilter f)
      : AttitudeStep(f.name, f.name, f.north), filter_(std::move(f.filter)) {
    filter_->seed_field(f.north.field_ut, f.north.dip_deg);  // a location: the model's |B| and dip
  }
  bool step(const ImuSample& sample) override { return filter_->update(sample); }
  bool attitude(nodes::AttitudeReport& report) const override {
    if (!filter_->initialized()) {
      return false;
    }
    report.q_world_body = filter_->q_world_body();
    const std::optional<Eigen::Matrix3d> cov = filter_->attitude_covariance();
    report.covariance = cov ? *cov : Eigen::Matrix3d::Zero();
    if (!cov) {
      report.covariance(0, 0) = -1.0;  // unknown (REP 145)
    }
    report.heading_status = filter_->heading_status();
    const SourceReports sources = filter_->sources();  // as the filter's live node fills them
    report.sources_fused = nodes::sources_fused_bits(sources);
    report.mag_trusted = nodes::source_fused(sources, poise::Source::kMag);
    return true;
  }
  void diagnostics(nodes::DiagnosticsReport& diag) const override {
    diag.sources = filter_->sources();
    diag.counters = filter_->rejections();
  }
  /// A delay recorded on `imu_info`: the filter takes it unless its configuration set one.
  bool published_imu_delay(double delay_s, const std::string& /*what*/) override {
    return filter_->take_published_imu_delay(delay_s);
  }

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

/// One message to write: a component's output, written after the input message that caused it,
/// or an input message copied through.
struct Output {
  uint64_t ordinal = 0;  ///< the input message it follows (or is)
  uint16_t channel = 0;
  uint32_t sequence = 0;  ///< input copied through: its recorded sequence
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

  /// Takes the outputs caused by the input message `ordinal`, in production order.
  std::vector<Output> take(uint64_t ordinal) {
    const auto it = outputs_.find(ordinal);
    if (it == outputs_.end()) {
      return {};
    }
    std::vector<Output> out = std::move(it->second);
    outputs_.erase(it);
    return out;
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
    outputs_[ordinal_].push_back(std::move(out));
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
  std::map<uint64_t, std::vector<Output>> outputs_;  // by the input message that caused them
};

}  // namespace

std::unique_ptr<nodes::EstimatorStep> filter_step(ProcessFilter filter) {
  return std::make_unique<FilterStep>(std::move(filter));
}

namespace {
/// Each component's notes (the IMU delay it used, other IMUs it did not follow) and counts.
void add_runner_totals(const std::vector<std::unique_ptr<nodes::StepRunner>>& runners, ProcessStats& stats) {
  for (const auto& r : runners) {
    const std::string& name = r->step().sensor_id();
    if (const nodes::ImuDelayChoice* d = r->step().imu_delay()) {
      stats.imu_delay_notes.push_back(name + ": " + d->describe());
    }
    if (const std::string other = r->other_imu_summary(); !other.empty()) {
      stats.imu_delay_notes.push_back(name + ": " + other);
    }
    stats.estimates[name] += r->published();
    stats.rejected[name] += r->rejected();
    stats.diagnostics[name] += r->diagnostics_published();
  }
}
}  // namespace

ProcessStats process_recording(const ProcessOptions& options, std::vector<ProcessFilter>& filters) {
  std::vector<ProcessComponent> components;
  for (ProcessFilter& f : filters) {
    components.push_back({filter_step(std::move(f)), nodes::NodeParams{}});
  }
  filters.clear();
  return process_recording(options, components);
}

namespace {

enum class InputKind { kNone, kImu, kVision, kVehicle };

/// Decodes `m` into `in` when it is one of the inputs the components take. Returns its kind
/// (kNone: not an input); `problem` is set when the payload is malformed.
InputKind decode_input(const MessageView& m, const ProcessOptions& options, bool wants_vision, bool wants_vehicle,
                       Input& in, std::optional<std::string>& problem) {
  if (m.schema == nullptr) {
    return InputKind::kNone;
  }
  const std::string& topic = m.channel->topic;
  const std::string& type = m.schema->name;
  if (topic == options.topics.imu && type == dds::type_names::kImuSample) {
    msg::ImuSample s;
    problem = decode<msg::ImuSamplePubSubType>(m, s);
    in.stamp_ns = s.header().stamp_ns();
    in.sample = std::move(s);
    return InputKind::kImu;
  }
  if (wants_vision && topic == options.topics.vision_pose && type == dds::type_names::kVisionPose) {
    msg::VisionPose s;
    problem = decode<msg::VisionPosePubSubType>(m, s);
    in.stamp_ns = s.capture_stamp_ns();
    in.sample = std::move(s);
    return InputKind::kVision;
  }
  if (wants_vehicle && topic == options.topics.vehicle_input && type == dds::type_names::kVehicleInput) {
    msg::VehicleInput s;
    problem = decode<msg::VehicleInputPubSubType>(m, s);
    in.stamp_ns = s.header().stamp_ns();
    in.sample = std::move(s);
    return InputKind::kVehicle;
  }
  return InputKind::kNone;
}

/// (stamp, ordinal): the processing order of kStamp (a stable sort by stamp).
using OrderKey = std::pair<int64_t, uint64_t>;

/// What the components take from the recording.
struct Wants {
  bool vision = false;
  bool vehicle = false;
};

/// What pass 1 finds before anything is run.
struct InputScan {
  uint64_t malformed_imu = 0;
  uint64_t malformed_vision = 0;
  uint64_t malformed_vehicle = 0;
  int64_t first_stamp_ns = 0;
  /// The farthest any input sits after its place in the stamp order (0 in recorded order).
  uint64_t window = 0;
  /// The IMU infos (`imu_info`) in file order: each component gets them before the first sample.
  std::vector<msg::ImuSensorInfo> imu_infos;
};

using Progress = std::function<void(uint64_t phase, uint64_t done)>;

/// The farthest any key sits after its place in the stamp order, and the first stamp in it.
std::pair<uint64_t, int64_t> reorder_window(const std::vector<OrderKey>& keys) {
  std::vector<uint64_t> file_index(keys.size());
  for (uint64_t i = 0; i < file_index.size(); ++i) {
    file_index[i] = i;
  }
  std::stable_sort(file_index.begin(), file_index.end(),
                   [&keys](uint64_t a, uint64_t b) { return keys[a].first < keys[b].first; });
  uint64_t window = 0;
  for (uint64_t j = 0; j < file_index.size(); ++j) {
    window = std::max(window, file_index[j] > j ? file_index[j] - j : 0);
  }
  return {window, keys[file_index.front()].first};
}

/// The part of the recording processed (ProcessOptions::start_s / end_s), in log time from the
/// first message's.
class LogCut {
 public:
  LogCut(const McapReader& reader, const ProcessOptions& options) {
    const uint64_t first = reader.report().start_ns;
    start_ns_ = at(first, options.start_s);
    end_ns_ = std::isfinite(options.end_s) ? at(first, options.end_s) : std::numeric_limits<uint64_t>::max();
  }
  [[nodiscard]] bool outside(const MessageView& m) const { return m.log_time_ns < start_ns_ || m.log_time_ns >= end_ns_; }

 private:
  static uint64_t at(uint64_t first_ns, double s) {
    if (!(s > 0.0)) {
      return first_ns;
    }
    const double ns = static_cast<double>(first_ns) + s * 1e9;
    return ns >= 1.8e19 ? std::numeric_limits<uint64_t>::max() : static_cast<uint64_t>(ns);
  }
  uint64_t start_ns_ = 0;
  uint64_t end_ns_ = std::numeric_limits<uint64_t>::max();
};

/// A malformed payload: counted, and described while fewer than kMaxDescribedSkips are.
void count_undecodable(const MessageView& m, const std::string& problem, ProcessStats& stats) {
  ++stats.undecodable;
  if (stats.undecodable_details.size() < kMaxDescribedSkips) {
    stats.undecodable_details.push_back(describe_position(m) + " on '" + m.channel->topic + "', " +
                                        std::to_string(m.size) + " bytes: " + problem);
  }
}

/// Pass 1, a scan: what is malformed (counted and named, never processed; the components'
/// diagnostics carry the totals from their first message), the first stamp, and how far the stamp
/// order strays from the file order. Only (stamp, ordinal) is kept per input, so the memory used
/// does not grow with the recording's payloads.
InputScan scan_inputs(const McapReader& reader, const ProcessOptions& options, const LogCut& cut, Wants wants,
                      const Progress& progress, ProcessStats& stats) {
  InputScan scan;
  std::vector<OrderKey> keys;  // valid inputs in file order
  MessageCursor cursor = reader.messages();
  uint64_t ordinal = 0;
  while (const MessageView* m = cursor.next()) {
    const uint64_t index = ordinal++;
    // the IMU's delay is a property of the sensor: taken from anywhere in the recording (a
    // transient-local info is recorded once, maybe before --start)
    if (m->schema != nullptr && m->channel->topic == options.topics.imu_info &&
        m->schema->name == dds::type_names::kImuSensorInfo) {
      msg::ImuSensorInfo info;
      const std::optional<std::string> problem = decode<msg::ImuSensorInfoPubSubType>(*m, info);
      if (problem) {
        count_undecodable(*m, *problem, stats);
      } else {
        ++stats.imu_infos;
        scan.imu_infos.push_back(std::move(info));
      }
      continue;
    }
    if (cut.outside(*m)) {
      continue;
    }
    ++stats.input_messages;
    progress(0, stats.input_messages);
    Input in;
    std::optional<std::string> problem;
    const InputKind kind = decode_input(*m, options, wants.vision, wants.vehicle, in, problem);
    if (kind == InputKind::kNone) {
      continue;
    }
    uint64_t* malformed = nullptr;
    switch (kind) {
      case InputKind::kImu: ++stats.imu_samples; malformed = &scan.malformed_imu; break;
      case InputKind::kVision: ++stats.vision_samples; malformed = &scan.malformed_vision; break;
      case InputKind::kVehicle: ++stats.vehicle_inputs; malformed = &scan.malformed_vehicle; break;
      case InputKind::kNone: break;
    }
    if (problem) {
      ++*malformed;
      count_undecodable(*m, *problem, stats);
      continue;
    }
    keys.emplace_back(in.stamp_ns, index);
  }
  stats.damaged_chunks = cursor.problems().size();
  for (const std::string& p : cursor.problems()) {
    stats.input_problems.push_back(p);
  }
  // The inputs are run in stamp order by a min-heap fed in file order: it sorts exactly when it
  // may hold `window` + 1 inputs, where `window` is the farthest any input sits after its place
  // in the stamp order (the vision latency in samples, typically; 0 in recorded order).
  scan.first_stamp_ns = keys.empty() ? 0 : keys.front().first;
  if (options.order == ProcessOrder::kStamp && !keys.empty()) {
    std::tie(scan.window, scan.first_stamp_ns) = reorder_window(keys);
  }
  return scan;
}

/// Input channels copied through (ids remapped), in id order: deterministic. Returns the map
/// from the recording's channel ids to the output's.
std::map<uint16_t, uint16_t> copy_input_channels(const McapReader& reader, McapWriter& writer) {
  std::map<uint16_t, uint16_t> schema_map;
  std::map<uint16_t, uint16_t> channel_map;
  for (const auto& [id, schema] : reader.schemas()) {
    schema_map[id] = writer.add_schema(schema.name, schema.encoding, schema.data);
  }
  for (const auto& [id, channel] : reader.channels()) {
    const uint16_t schema_id = channel.schema_id == 0 ? 0 : schema_map.at(channel.schema_id);
    try {
      channel_map[id] = writer.add_channel(schema_id, channel.topic, channel.message_encoding, channel.metadata);
    } catch (const WriteError& e) {
      throw WriteError("the recording has " + std::to_string(reader.channels().size()) +
                       " channels, copied into the output with the estimates' own: " + e.what());
    }
  }
  return channel_map;
}

/// Pass 2: runs the inputs in processing order and writes in one stream. Each input message is
/// copied through, then the outputs its input caused; a message waits only while an input at or
/// before it is not yet run.
class OrderedRun {
 public:
  OrderedRun(const ProcessOptions& options, McapWriter& writer, McapOutputs& outputs,
             std::vector<std::unique_ptr<nodes::StepRunner>>& runners, uint64_t window, int64_t& now_ns,
             int64_t& log_clock, ProcessStats& stats)
      : options_(options), writer_(writer), outputs_(outputs), runners_(runners), window_(window),
        now_ns_(now_ns), log_clock_(log_clock), stats_(stats) {}

  /// Message `m`, the `index`-th of the recording (its input `in` when it is a valid one).
  void add(const MessageView& m, uint64_t index, const std::map<uint16_t, uint16_t>& channel_map,
           std::optional<Input> in) {
    Output p;
    p.ordinal = index;
    p.log_time_ns = m.log_time_ns;
    if (options_.copy_input) {
      p.channel = channel_map.at(m.channel->id);
      p.sequence = m.sequence;
      p.publish_time_ns = m.publish_time_ns;
      p.data.assign(m.data, m.data + m.size);
    }
    to_write_.push_back(std::move(p));
    if (in) {
      in->ordinal = index;
      in->log_time_ns = m.log_time_ns;
      const OrderKey key = options_.order == ProcessOrder::kStamp ? OrderKey{in->stamp_ns, index} : OrderKey{0, index};
      not_run_.insert(index);
      to_run_.emplace(key, std::move(*in));
      if (to_run_.size() > window_) {
        run_next();
      }
    }
    write_ready(false);
  }

  /// Runs what is left and writes everything.
  void finish() {
    while (!to_run_.empty()) {
      run_next();
    }
    write_ready(true);
  }

 private:
  using Queued = std::pair<OrderKey, Input>;
  struct Later {
    bool operator()(const Queued& a, const Queued& b) const { return a.first > b.first; }
  };

  void run_input(const Input& in) {
    now_ns_ = in.stamp_ns;
    outputs_.set_trigger(in.ordinal, in.log_time_ns);
    if (const auto* imu = std::get_if<msg::ImuSample>(&in.sample)) {
      // samples the recording lacks (lost before the recorder): said, since live had them
      const uint32_t seq = imu->header().seq();
      const auto [it, first] = last_seq_.try_emplace(imu->sensor_id().to_string(), seq);
      if (!first && seq - it->second > 1U && seq - it->second < (1U << 31)) {
        ++stats_.imu_gaps;
        stats_.imu_missing += seq - it->second - 1U;
      }
      it->second = seq;
      const ImuSample sample = dds::from_msg(*imu);
      const std::string source = imu->sensor_id().to_string();
      for (auto& r : runners_) {
        r->imu(sample, source, kWriterId, outputs_);
      }
    } else if (const auto* vision = std::get_if<msg::VisionPose>(&in.sample)) {
      for (auto& r : runners_) {
        r->vision(*vision, kWriterId);
      }
    } else if (const auto* vehicle = std::get_if<msg::VehicleInput>(&in.sample)) {
      for (auto& r : runners_) {
        r->vehicle_input(*vehicle, kWriterId);
      }
    }
  }

  void run_next() {
    const Queued& next = to_run_.top();
    run_input(next.second);
    not_run_.erase(next.second.ordinal);
    to_run_.pop();
  }

  void write_ready(bool all) {
    while (!to_write_.empty() && (all || not_run_.empty() || to_write_.front().ordinal < *not_run_.begin())) {
      const Output& p = to_write_.front();
      log_clock_ = static_cast<int64_t>(p.log_time_ns);
      if (options_.copy_input) {
        writer_.write(p.channel, p.sequence, p.log_time_ns, p.publish_time_ns, p.data.data(), p.data.size());
      }
      for (const Output& o : outputs_.take(p.ordinal)) {
        log_clock_ = static_cast<int64_t>(o.log_time_ns);
        writer_.write(o.channel, out_seq_[o.channel]++, o.log_time_ns, o.publish_time_ns, o.data.data(),
                      o.data.size());
        ++stats_.per_topic[outputs_.topic_of(o.channel)];
      }
      to_write_.pop_front();
    }
  }

  static constexpr const char* kWriterId = "recording";  // one publisher per input: no restarts offline

  const ProcessOptions& options_;
  McapWriter& writer_;
  McapOutputs& outputs_;
  std::vector<std::unique_ptr<nodes::StepRunner>>& runners_;
  const uint64_t window_;
  int64_t& now_ns_;
  int64_t& log_clock_;
  ProcessStats& stats_;
  std::map<std::string, uint32_t> last_seq_;  // IMU seq gaps per sensor, in processing order
  std::priority_queue<Queued, std::vector<Queued>, Later> to_run_;
  std::set<uint64_t> not_run_;    // ordinals of the inputs in to_run_
  std::deque<Output> to_write_;   // input messages waiting to be written (with their outputs)
  std::map<uint16_t, uint32_t> out_seq_;
};

}  // namespace

ProcessStats process_recording(const ProcessOptions& options, std::vector<ProcessComponent>& components) {
  ProcessStats stats;
  const McapReader reader = McapReader::open_file(options.input);
  stats.input_complete = reader.report().complete;
  stats.input_problems = reader.report().problems;
  stats.corrupt_in_file = reader.report().corrupt;

  Wants wants;
  for (const ProcessComponent& c : components) {
    wants.vision = wants.vision || c.step->uses_vision();
    wants.vehicle = wants.vehicle || c.step->uses_vehicle_input();
  }
  const uint64_t total = std::max<uint64_t>(1, reader.report().messages);
  const Progress progress = [&options, total](uint64_t phase, uint64_t done) {
    if (options.progress) {
      options.progress(phase * total + done, 2 * total);  // scan, then run + write
    }
  };
  const LogCut cut(reader, options);
  const InputScan scan = scan_inputs(reader, options, cut, wants, progress, stats);
  stats.reorder_window = scan.window;

  int64_t log_clock = 0;  // the writer's chunk clock: recording time, never the wall clock
  WriterOptions wopt;
  wopt.clock = [&log_clock] { return log_clock; };
  // Never opened over the input; written beside the output's name and renamed at the end, so a
  // failed run leaves the output as it was.
  std::unique_ptr<ReplacingFile> output;
  std::unique_ptr<Sink> sink;
  try {
    refuse_output_over_input(options.output, {options.input});
    output = std::make_unique<ReplacingFile>(options.output);
    sink = open_file_sink(output->temporary());
  } catch (const IoError& e) {
    throw WriteError(e.what());
  }
  McapWriter writer(std::move(sink), wopt);
  const std::map<uint16_t, uint16_t> channel_map =
      options.copy_input ? copy_input_channels(reader, writer) : std::map<uint16_t, uint16_t>{};

  // The components, each in the node's shape; time = the stamp of the input being processed.
  McapOutputs outputs(writer, options);
  int64_t now_ns = scan.first_stamp_ns;
  std::vector<std::unique_ptr<nodes::StepRunner>> runners;
  for (ProcessComponent& c : components) {
    outputs.declare(*c.step, options.topics);
    // No arrival times offline (the clock is the stamps): input ages are a live matter.
    c.params.input_age = nodes::AgeMethod::kOff;
    auto runner = std::make_unique<nodes::StepRunner>(std::move(c.step), c.params, options.topics,
                                                      [&now_ns] { return now_ns; });
    runner->imu_malformed().store(scan.malformed_imu);
    runner->vision_malformed().store(scan.malformed_vision);
    runner->vehicle_input_malformed().store(scan.malformed_vehicle);
    for (const msg::ImuSensorInfo& info : scan.imu_infos) {
      const std::string problem = runner->imu_info(info);
      if (!problem.empty()) {
        stats.imu_delay_notes.push_back(runner->step().sensor_id() + ": " + problem);
      }
    }
    runners.push_back(std::move(runner));
  }
  components.clear();

  OrderedRun run(options, writer, outputs, runners, scan.window, now_ns, log_clock, stats);
  MessageCursor cursor = reader.messages();
  uint64_t ordinal = 0;
  while (const MessageView* m = cursor.next()) {
    const uint64_t index = ordinal++;
    progress(1, ordinal);
    if (cut.outside(*m)) {
      continue;
    }
    Input in;
    std::optional<std::string> problem;
    const bool valid_input =
        decode_input(*m, options, wants.vision, wants.vehicle, in, problem) != InputKind::kNone && !problem;
    run.add(*m, index, channel_map, valid_input ? std::optional<Input>(std::move(in)) : std::nullopt);
  }
  run.finish();
  add_runner_totals(runners, stats);
  writer.close();
  try {
    output->commit();
  } catch (const IoError& e) {
    throw WriteError(e.what());
  }
  return stats;
}

}  // namespace poise::record
