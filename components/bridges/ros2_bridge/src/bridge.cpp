#include "poise/ros2_bridge/bridge.h"

#include "poise/core/yaml_params.h"

#include "poise/dds/convert.h"
#include "poise/dds/participant.h"
#include "poise/nodes/reports.h"

#include <poise/msg/diagnosticsPubSubTypes.h>

#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/ros2/diagnostic_msgsPubSubTypes.h>
#include <poise/ros2/geometry_msgsPubSubTypes.h>
#include <poise/ros2/nav_msgsPubSubTypes.h>
#include <poise/ros2/sensor_msgsPubSubTypes.h>
#include <poise/ros2/tf2_msgsPubSubTypes.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <condition_variable>
#include <thread>
#include <ctime>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <sstream>

namespace poise::ros2 {
namespace {

using runtime::ConfigError;

std::string read_string(const YAML::Node& map, const std::string& key, const std::string& fallback,
                        const std::string& where) {
  if (!map[key]) {
    return fallback;
  }
  if (map[key].IsNull()) {  // never silently the default (or the string "null")
    throw ConfigError(where + ": '" + key + "' has no value (empty or ~): give one, or leave the key out");
  }
  try {
    return map[key].as<std::string>();
  } catch (const YAML::Exception&) {
    throw ConfigError(where + ": '" + key + "' must be a string");
  }
}

template <typename T>
T read_value(const YAML::Node& map, const std::string& key, const T& fallback, const std::string& where,
             const char* what) {
  if (!map[key]) {
    return fallback;
  }
  if (map[key].IsNull()) {  // never silently the default (or the string "null")
    throw ConfigError(where + ": '" + key + "' has no value (empty or ~): give one, or leave the key out");
  }
  try {
    return map[key].as<T>();
  } catch (const YAML::Exception&) {
    throw ConfigError(where + ": '" + key + "' must be " + what);
  }
}

/// A ROS name checked (the DDS topic is derived from it), normalised to start with '/'.
std::string ros_name(const std::string& name, const std::string& where) {
  try {
    return "/" + dds_topic(name).substr(3);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(where + ": " + e.what());
  }
}

/// A frame id: non-empty, no leading '/' (tf2 refuses those), characters [A-Za-z0-9_/].
std::string frame_id(const std::string& id, const std::string& where) {
  bool ok = !id.empty() && id.front() != '/';
  for (char c : id) {
    ok = ok && (std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_' || c == '/');
  }
  if (!ok) {
    throw ConfigError(where + ": frame id '" + id +
                      "' must be non-empty, use [A-Za-z0-9_/] and not start with '/' (tf2)");
  }
  return id;
}

int64_t clock_ns(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

BridgeConfig parse_bridge_config(const YAML::Node& params, const std::string& origin) {
  BridgeConfig c;
  if (!params || params.IsNull()) {
    return c;
  }
  const std::string where = origin + ": ros2_bridge";
  check_known_keys<ConfigError>(params, {"namespace", "world_frame", "body_frame", "stamps", "out", "in"}, where);
  c.ros_namespace = read_string(params, "namespace", c.ros_namespace, where);
  if (c.ros_namespace != "/" && !c.ros_namespace.empty()) {
    c.ros_namespace = ros_name(c.ros_namespace, where + " namespace");
  } else {
    c.ros_namespace.clear();
  }
  c.frames.world = frame_id(read_string(params, "world_frame", c.frames.world, where), where + " world_frame");
  c.frames.body = frame_id(read_string(params, "body_frame", c.frames.body, where), where + " body_frame");
  const std::string stamps = read_string(params, "stamps", "realtime", where);
  if (stamps != "realtime" && stamps != "sensor") {
    throw ConfigError(where + ": stamps must be realtime or sensor, not '" + stamps + "'");
  }
  c.realtime_stamps = stamps == "realtime";
  if (const YAML::Node out = params["out"]) {
    const std::string w = where + " out";
    check_known_keys<ConfigError>(out, {"attitude", "pose", "imu", "altitude", "tf"}, where, "out.");
    c.attitude = read_value<std::vector<std::string>>(out, "attitude", {}, w, "a list of filter ids");
    c.pose = read_value<std::vector<std::string>>(out, "pose", {}, w, "a list of filter ids");
    c.imu = read_value<bool>(out, "imu", false, w, "true or false");
    c.altitude = read_value<bool>(out, "altitude", false, w, "true or false");
    c.tf = read_string(out, "tf", "", w);
    for (const auto& f : c.attitude) {
      ros_name(f, w + " attitude");
    }
    for (const auto& f : c.pose) {
      ros_name(f, w + " pose");
    }
    if (!c.tf.empty() && c.tf.rfind("attitude/", 0) != 0 && c.tf.rfind("pose/", 0) != 0) {
      throw ConfigError(w + ": tf must be attitude/<filter>, pose/<filter> or \"\", not '" + c.tf + "'");
    }
  }
  if (const YAML::Node in = params["in"]) {
    const std::string w = where + " in";
    check_known_keys<ConfigError>(in, {"imu", "mag", "pressure", "pair_tolerance_s", "stale_s"}, where, "in.");
    c.in_imu = read_string(in, "imu", "", w);
    if (c.in_imu.empty()) {
      throw ConfigError(w + ": 'imu' (the sensor_msgs/Imu topic) is required for input");
    }
    c.in_imu = ros_name(c.in_imu, w + " imu");
    c.in_mag = read_string(in, "mag", "", w);
    c.in_mag = c.in_mag.empty() ? c.in_mag : ros_name(c.in_mag, w + " mag");
    c.in_pressure = read_string(in, "pressure", "", w);
    c.in_pressure = c.in_pressure.empty() ? c.in_pressure : ros_name(c.in_pressure, w + " pressure");
    c.pair_tolerance_s = read_value<double>(in, "pair_tolerance_s", c.pair_tolerance_s, w, "a number (s)");
    c.stale_s = read_value<double>(in, "stale_s", c.stale_s, w, "a number (s)");
    if (!(c.pair_tolerance_s >= 0.0 && c.pair_tolerance_s <= 1.0)) {
      throw ConfigError(w + ": pair_tolerance_s must be in [0, 1] (s)");
    }
    if (!(c.stale_s > 0.0 && c.stale_s <= 60.0)) {
      throw ConfigError(w + ": stale_s must be in (0, 60] (s)");
    }
  }
  return c;
}

std::vector<BridgedTopic> bridged_topics(const BridgeConfig& c, const dds::TopicNames& names) {
  std::vector<BridgedTopic> out;
  const auto add = [&out](const std::string& ros, const std::string& type, const std::string& poise) {
    out.push_back({ros, dds_topic(ros), type, poise});
  };
  const std::string& ns = c.ros_namespace;
  for (const auto& f : c.attitude) {
    add(ns + "/" + f + "/imu", "sensor_msgs/msg/Imu", names.attitude(f));
    add(ns + "/" + f + "/heading_status", "diagnostic_msgs/msg/DiagnosticArray", names.attitude(f));
  }
  for (const auto& f : c.pose) {
    add(ns + "/" + f + "/pose", "geometry_msgs/msg/PoseWithCovarianceStamped", names.pose(f));
    add(ns + "/" + f + "/odom", "nav_msgs/msg/Odometry", names.pose(f));
  }
  if (c.imu) {
    add(ns + "/imu/data_raw", "sensor_msgs/msg/Imu", names.imu);
    add(ns + "/imu/mag", "sensor_msgs/msg/MagneticField", names.imu);
    add(ns + "/imu/pressure", "sensor_msgs/msg/FluidPressure", names.imu);
  }
  if (c.altitude) {
    add(ns + "/altitude/odom", "nav_msgs/msg/Odometry", names.altitude);
  }
  if (!c.tf.empty()) {
    add("/tf", "tf2_msgs/msg/TFMessage", c.tf);
  }
  if (!c.in_imu.empty()) {
    add(c.in_imu, "sensor_msgs/msg/Imu", names.imu);
  }
  if (!c.in_mag.empty()) {
    add(c.in_mag, "sensor_msgs/msg/MagneticField", names.imu);
  }
  if (!c.in_pressure.empty()) {
    add(c.in_pressure, "sensor_msgs/msg/FluidPressure", names.imu);
  }
  return out;
}

namespace {

/// The running bridge. Every callback runs on a Fast DDS thread and takes mutex_.
class Bridge : public runtime::Component {
 public:
  Bridge(const runtime::ComponentSpec& spec, runtime::HostContext& host)
      : host_(host),
        sensor_id_(spec.name),
        config_(parse_bridge_config(spec.params, spec.origin)),
        offset_ns_(config_.realtime_stamps ? clock_ns(CLOCK_REALTIME) - clock_ns(CLOCK_MONOTONIC) : 0),
        assembler_(input_config(config_, offset_ns_)) {
    // Refuse loops: an input topic that is also an output.
    const auto topics = bridged_topics(config_, host.topics);
    for (const std::string& in : {config_.in_imu, config_.in_mag, config_.in_pressure}) {
      const auto uses = std::count_if(topics.begin(), topics.end(),
                                      [&in](const BridgedTopic& t) { return t.ros_name == in; });
      if (!in.empty() && uses > 1) {
        throw ConfigError(spec.origin + ": ros2_bridge: '" + in +
                          "' is used more than once: inputs and outputs need distinct topics (an input "
                          "that is also an output would loop)");
      }
    }
    P& p = host.participant;
    const std::string& ns = config_.ros_namespace;
    for (const auto& f : config_.attitude) {
      attitude_out_[f] = std::make_unique<ImuWriter>(p, dds_topic(ns + "/" + f + "/imu"), kOut);
      heading_out_[f] = std::make_unique<DiagWriter>(p, dds_topic(ns + "/" + f + "/heading_status"), kOut);
    }
    for (const auto& f : config_.pose) {
      pose_out_[f] = std::make_unique<PoseWriter>(p, dds_topic(ns + "/" + f + "/pose"), kOut);
      odom_out_[f] = std::make_unique<OdomWriter>(p, dds_topic(ns + "/" + f + "/odom"), kOut);
    }
    if (config_.imu) {
      raw_out_ = std::make_unique<ImuWriter>(p, dds_topic(ns + "/imu/data_raw"), kOut);
      mag_out_ = std::make_unique<MagWriter>(p, dds_topic(ns + "/imu/mag"), kOut);
      pressure_out_ = std::make_unique<PressureWriter>(p, dds_topic(ns + "/imu/pressure"), kOut);
    }
    if (config_.altitude) {
      altitude_out_ = std::make_unique<OdomWriter>(p, dds_topic(ns + "/altitude/odom"), kOut);
    }
    if (!config_.tf.empty()) {
      tf_out_ = std::make_unique<TfWriter>(p, dds_topic("/tf"), kOut);
    }
    if (!config_.in_imu.empty()) {
      imu_in_writer_ = std::make_unique<dds::Writer<msg::ImuSamplePubSubType>>(p, host.topics.imu,
                                                                                dds::QosKind::kSensor);
    }
  }
  ~Bridge() override { Bridge::stop(); }

  void start() override {
    running_.store(true);
    if (!timer_.joinable()) {
      {
        std::lock_guard<std::mutex> lock(timer_mutex_);
        timer_stop_ = false;
      }
      timer_ = std::thread([this] { run_timer(); });
    }
    P& p = host_.participant;
    const auto& names = host_.topics;
    const bool needs_imu = config_.imu || !config_.attitude.empty() || !config_.pose.empty();
    if (needs_imu && !imu_reader_) {
      imu_reader_ = std::make_unique<dds::Reader<msg::ImuSamplePubSubType>>(
          p, names.imu, dds::QosKind::kSensor, [this](const msg::ImuSample& m, const auto&) { on_imu(m); });
    }
    for (const auto& f : config_.attitude) {
      if (attitude_readers_.count(f) == 0) {
        attitude_readers_[f] = std::make_unique<dds::Reader<msg::AttitudeEstimatePubSubType>>(
            p, names.attitude(f), dds::QosKind::kEstimate,
            [this, f](const msg::AttitudeEstimate& m, const auto&) { on_attitude(f, m); });
      }
    }
    if (config_.tf.rfind("attitude/", 0) == 0 && attitude_readers_.count(config_.tf.substr(9)) == 0) {
      const std::string f = config_.tf.substr(9);
      attitude_readers_[f] = std::make_unique<dds::Reader<msg::AttitudeEstimatePubSubType>>(
          p, names.attitude(f), dds::QosKind::kEstimate,
          [this, f](const msg::AttitudeEstimate& m, const auto&) { on_attitude(f, m); });
    }
    std::vector<std::string> poses = config_.pose;
    if (config_.tf.rfind("pose/", 0) == 0) {
      poses.push_back(config_.tf.substr(5));
    }
    for (const auto& f : poses) {
      if (pose_readers_.count(f) == 0) {
        pose_readers_[f] = std::make_unique<dds::Reader<msg::PoseEstimatePubSubType>>(
            p, names.pose(f), dds::QosKind::kEstimate,
            [this, f](const msg::PoseEstimate& m, const auto&) { on_pose(f, m); });
      }
    }
    if (config_.altitude && !altitude_reader_) {
      altitude_reader_ = std::make_unique<dds::Reader<msg::AltitudeEstimatePubSubType>>(
          p, names.altitude, dds::QosKind::kEstimate,
          [this](const msg::AltitudeEstimate& m, const auto&) { on_altitude(m); });
    }
    if (!config_.in_imu.empty() && !ros_imu_reader_) {
      ros_imu_reader_ = std::make_unique<dds::Reader<ros_sensor::Imu_PubSubType>>(
          p, dds_topic(config_.in_imu), dds::QosKind::kSensor,
          [this](const ros_sensor::Imu_& m, const auto&) {
            on_ros([&] { return assembler_.on_imu(m); });
          });
    }
    if (!config_.in_mag.empty() && !ros_mag_reader_) {
      ros_mag_reader_ = std::make_unique<dds::Reader<ros_sensor::MagneticField_PubSubType>>(
          p, dds_topic(config_.in_mag), dds::QosKind::kSensor,
          [this](const ros_sensor::MagneticField_& m, const auto&) {
            on_ros([&] { return assembler_.on_mag(m); });
          });
    }
    if (!config_.in_pressure.empty() && !ros_pressure_reader_) {
      ros_pressure_reader_ = std::make_unique<dds::Reader<ros_sensor::FluidPressure_PubSubType>>(
          p, dds_topic(config_.in_pressure), dds::QosKind::kSensor,
          [this](const ros_sensor::FluidPressure_& m, const auto&) {
            on_ros([&] { return assembler_.on_pressure(m); });
          });
    }
  }

  void stop() override {
    running_.store(false);
    // No callback runs after a reader is gone.
    ros_imu_reader_.reset();
    ros_mag_reader_.reset();
    ros_pressure_reader_.reset();
    imu_reader_.reset();
    attitude_readers_.clear();
    pose_readers_.clear();
    altitude_reader_.reset();
    {
      std::lock_guard<std::mutex> lock(timer_mutex_);
      timer_stop_ = true;
    }
    timer_cv_.notify_all();
    if (timer_.joinable()) {
      timer_.join();
    }
  }

  /// Messages sent to ROS 2 and IMU samples from it (the service watchdog's health check).
  [[nodiscard]] std::optional<uint64_t> produced() const override {
    const Counts c = counts();
    return c.ros_out + c.imu_out;
  }

  [[nodiscard]] std::string status() const override {
    const Counts c = counts();
    std::ostringstream os;
    os << "ros out " << c.ros_out;
    if (!config_.in_imu.empty()) {
      os << ", ros imu in -> poise imu " << c.imu_out << " (mag paired " << c.mag_paired
         << ", pressure paired " << c.pressure_paired << ")";
    }
    os << ", rejected " << c.rejected_total;
    for (const auto& [reason, n] : c.rejected) {
      os << " " << reason << "=" << n;
    }
    return os.str();
  }

 private:
  using P = dds::Participant;
  using ImuWriter = dds::Writer<ros_sensor::Imu_PubSubType>;
  using MagWriter = dds::Writer<ros_sensor::MagneticField_PubSubType>;
  using PressureWriter = dds::Writer<ros_sensor::FluidPressure_PubSubType>;
  using PoseWriter = dds::Writer<ros_geo::PoseWithCovarianceStamped_PubSubType>;
  using OdomWriter = dds::Writer<ros_nav::Odometry_PubSubType>;
  using TfWriter = dds::Writer<ros_tf::TFMessage_PubSubType>;
  using DiagWriter = dds::Writer<ros_diag::DiagnosticArray_PubSubType>;
  static constexpr dds::QosKind kOut = dds::QosKind::kEstimate;  // reliable, volatile
  static constexpr std::size_t kRecentSamples = 512;              // IMU samples kept for pairing
  static constexpr std::size_t kMaxPending = 64;                  // estimates waiting for theirs

  static InputConfig input_config(const BridgeConfig& c, int64_t offset_ns) {
    InputConfig in;
    in.mag = !c.in_mag.empty();
    in.pressure = !c.in_pressure.empty();
    in.pair_tolerance_s = c.pair_tolerance_s;
    in.stale_s = c.stale_s;
    in.offset_ns = offset_ns;
    return in;
  }

  /// Writes `m` when it is finite and its stamp is a ROS time; otherwise counts `what`.
  template <class Writer, class Message>
  bool write(Writer* writer, const Message& m, int64_t stamp_ns, const std::string& what) {
    if (writer == nullptr) {
      return false;
    }
    if (!to_ros_time(stamp_ns, offset_ns_)) {
      ++refused_[what + "_bad_stamp"];
      return false;
    }
    if (!all_finite(m)) {
      ++refused_[what + "_non_finite"];
      return false;
    }
    writer->write(m);
    ++written_;
    return true;
  }

  const msg::ImuSample* find_sample(int64_t stamp_ns) const {
    for (auto it = recent_.rbegin(); it != recent_.rend(); ++it) {
      if (it->header().stamp_ns() == stamp_ns) {
        return &*it;
      }
    }
    return nullptr;
  }

  /// Runs `publish` with the IMU sample of `stamp_ns` now, or once it arrives (an estimate can
  /// overtake its sample: another reader of the same sample may run first); without one when a
  /// later sample came first, no sample ever came, or too many wait.
  void with_sample(int64_t stamp_ns, std::function<void(const msg::ImuSample*)> publish) {
    const msg::ImuSample* sample = find_sample(stamp_ns);
    if (sample != nullptr || recent_.empty() || recent_.back().header().stamp_ns() > stamp_ns) {
      publish(sample);
      return;
    }
    pending_.push_back({stamp_ns, std::move(publish)});
    if (pending_.size() > kMaxPending) {
      pending_.front().publish(nullptr);
      pending_.pop_front();
    }
  }

  void on_imu(const msg::ImuSample& m) {
    if (!running_.load()) {
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    recent_.push_back(m);
    if (recent_.size() > kRecentSamples) {
      recent_.pop_front();
    }
    const int64_t t = m.header().stamp_ns();
    while (!pending_.empty() && pending_.front().stamp_ns <= t) {
      pending_.front().publish(pending_.front().stamp_ns == t ? &recent_.back() : nullptr);
      pending_.pop_front();
    }
    if (config_.imu) {
      write(raw_out_.get(), sample_to_imu(m, config_.frames, offset_ns_), t, "imu_data_raw");
      if (const auto mag = sample_to_mag(m, config_.frames, offset_ns_)) {
        write(mag_out_.get(), *mag, t, "imu_mag");
      }
      if (const auto pressure = sample_to_pressure(m, config_.frames, offset_ns_)) {
        write(pressure_out_.get(), *pressure, t, "imu_pressure");
      }
    }
  }

  void on_attitude(const std::string& filter, const msg::AttitudeEstimate& m) {
    if (!running_.load()) {
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const int64_t t = m.header().stamp_ns();
    if (config_.tf == "attitude/" + filter) {
      write(tf_out_.get(), to_tf(t, m.q_world_body(), msg::Vector3(), config_.frames, offset_ns_), t, "tf");
    }
    const auto out = attitude_out_.find(filter);
    if (out == attitude_out_.end()) {
      return;
    }
    ImuWriter* writer = out->second.get();
    with_sample(t, [this, writer, m, filter](const msg::ImuSample* sample) {
      // The companion heading status goes out only with its estimate: a rejected estimate (NaN,
      // a stamp ROS cannot hold) is counted once, as attitude_<f>, and says nothing on ROS 2.
      if (write(writer, attitude_to_imu(m, sample, config_.frames, offset_ns_), m.header().stamp_ns(),
                "attitude_" + filter)) {
        write(heading_out_.at(filter).get(), heading_status_to_diagnostics(m, filter, config_.frames, offset_ns_),
              m.header().stamp_ns(), "heading_" + filter);
      }
    });
  }

  void on_pose(const std::string& filter, const msg::PoseEstimate& m) {
    if (!running_.load()) {
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const int64_t t = m.header().stamp_ns();
    if (config_.tf == "pose/" + filter) {
      write(tf_out_.get(), to_tf(t, m.q_world_body(), m.position_m(), config_.frames, offset_ns_), t, "tf");
    }
    const auto pose = pose_out_.find(filter);
    if (pose == pose_out_.end()) {
      return;
    }
    write(pose->second.get(), pose_to_ros(m, config_.frames, offset_ns_), t, "pose_" + filter);
    OdomWriter* odom = odom_out_.at(filter).get();
    with_sample(t, [this, odom, m, filter](const msg::ImuSample* sample) {
      write(odom, pose_to_odometry(m, sample, config_.frames, offset_ns_), m.header().stamp_ns(),
            "odom_" + filter);
    });
  }

  void on_altitude(const msg::AltitudeEstimate& m) {
    if (!running_.load()) {
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const int64_t t = m.header().stamp_ns();
    write(altitude_out_.get(), altitude_to_odometry(m, config_.frames, offset_ns_), t, "altitude");
  }

  /// Steps the assembler (under input_mutex_), then publishes what it completed with no lock
  /// held: in-process readers of `imu` (the estimators) run inside write() and publish estimates
  /// that this bridge reads (on_attitude takes mutex_).
  template <class Step>
  void on_ros(Step step) {
    if (!running_.load()) {
      return;
    }
    std::vector<ImuSample> samples;
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      samples = step();
    }
    for (const ImuSample& s : samples) {
      imu_in_writer_->write(dds::to_msg(s, sensor_id_));
    }
  }

  struct Counts {
    uint64_t ros_out = 0;          // ROS messages written
    uint64_t imu_out = 0;          // poise imu samples made from ROS input
    uint64_t mag_paired = 0;
    uint64_t pressure_paired = 0;
    std::map<std::string, uint64_t> rejected;  // in: the assembler's reasons; out: <what>_non_finite, _bad_stamp
    uint64_t rejected_total = 0;
  };
  Counts counts() const {
    std::lock_guard<std::mutex> input_lock(input_mutex_);
    std::lock_guard<std::mutex> lock(mutex_);
    Counts c;
    c.ros_out = written_;
    c.imu_out = assembler_.emitted();
    c.mag_paired = assembler_.paired_mag();
    c.pressure_paired = assembler_.paired_pressure();
    c.rejected = assembler_.rejected();
    c.rejected.insert(refused_.begin(), refused_.end());  // disjoint names (imu_*/mag_* vs <what>_*)
    for (const auto& [reason, n] : c.rejected) {
      c.rejected_total += n;
    }
    return c;
  }

  /// FilterDiagnostics on `diagnostics` once a second: the counters, as every node reports.
  void run_timer() {
    std::unique_lock<std::mutex> timer_lock(timer_mutex_);
    while (!timer_cv_.wait_for(timer_lock, std::chrono::seconds(1), [this] { return timer_stop_; })) {
      nodes::DiagnosticsReport report;
      report.stamp_ns = clock_ns(CLOCK_MONOTONIC);
      report.seq = diagnostics_seq_++;
      report.component = "ros2_bridge";
      const Counts c = counts();
      report.counters = c.rejected;
      report.counters["ros_messages_out"] = c.ros_out;
      report.counters["imu_samples_out"] = c.imu_out;
      report.counters["mag_paired"] = c.mag_paired;
      report.counters["pressure_paired"] = c.pressure_paired;
      report.counters["samples_rejected"] = c.rejected_total;
      diagnostics_writer_.write(nodes::to_diagnostics_msg(report, sensor_id_));
    }
  }

  struct Pending {
    int64_t stamp_ns;
    std::function<void(const msg::ImuSample*)> publish;
  };

  runtime::HostContext& host_;
  std::string sensor_id_;
  BridgeConfig config_;
  int64_t offset_ns_;
  std::atomic<bool> running_{false};
  mutable std::mutex mutex_;
  mutable std::mutex input_mutex_;
  ImuAssembler assembler_;  // guarded by input_mutex_ (the ROS input callbacks)
  std::deque<msg::ImuSample> recent_;
  std::deque<Pending> pending_;
  uint64_t written_ = 0;
  std::map<std::string, uint64_t> refused_;
  std::map<std::string, std::unique_ptr<ImuWriter>> attitude_out_;
  std::map<std::string, std::unique_ptr<DiagWriter>> heading_out_;  // the attitude Imu's heading status
  std::map<std::string, std::unique_ptr<PoseWriter>> pose_out_;
  std::map<std::string, std::unique_ptr<OdomWriter>> odom_out_;
  std::unique_ptr<ImuWriter> raw_out_;
  std::unique_ptr<MagWriter> mag_out_;
  std::unique_ptr<PressureWriter> pressure_out_;
  std::unique_ptr<OdomWriter> altitude_out_;
  std::unique_ptr<TfWriter> tf_out_;
  std::unique_ptr<dds::Writer<msg::ImuSamplePubSubType>> imu_in_writer_;
  std::unique_ptr<dds::Reader<msg::ImuSamplePubSubType>> imu_reader_;
  std::map<std::string, std::unique_ptr<dds::Reader<msg::AttitudeEstimatePubSubType>>> attitude_readers_;
  std::map<std::string, std::unique_ptr<dds::Reader<msg::PoseEstimatePubSubType>>> pose_readers_;
  std::unique_ptr<dds::Reader<msg::AltitudeEstimatePubSubType>> altitude_reader_;
  std::unique_ptr<dds::Reader<ros_sensor::Imu_PubSubType>> ros_imu_reader_;
  std::unique_ptr<dds::Reader<ros_sensor::MagneticField_PubSubType>> ros_mag_reader_;
  std::unique_ptr<dds::Reader<ros_sensor::FluidPressure_PubSubType>> ros_pressure_reader_;
  dds::Writer<msg::FilterDiagnosticsPubSubType> diagnostics_writer_{host_.participant, host_.topics.diagnostics,
                                                                    dds::QosKind::kEstimate};
  uint32_t diagnostics_seq_ = 0;
  std::mutex timer_mutex_;
  std::condition_variable timer_cv_;
  bool timer_stop_ = false;
  std::thread timer_;
};

}  // namespace

void register_ros2_bridge(runtime::ComponentRegistry& registry) {
  registry.add({"ros2_bridge",
                "poise <-> ROS 2 over plain DDS: estimates, raw IMU and /tf out as ROS 2 messages; a "
                "ROS 2 IMU driver's sensor_msgs/Imu (+ MagneticField, FluidPressure) in as poise imu",
                [](const runtime::ComponentSpec& spec, runtime::HostContext& host) {
                  return std::make_unique<Bridge>(spec, host);
                }});
}

}  // namespace poise::ros2

namespace poise::runtime {
void register_ros2_bridge_component(ComponentRegistry& registry) { ros2::register_ros2_bridge(registry); }
}  // namespace poise::runtime
