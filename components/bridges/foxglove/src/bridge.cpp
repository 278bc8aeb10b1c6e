#include "poise/foxglove/bridge.h"

#include "poise/dds/participant.h"
#include "poise/schema/cdr.h"
#include "poise/schema/observer.h"
#include "poise/foxglove/panels.h"
#include "poise/nodes/reports.h"

#include <poise/msg/diagnosticsPubSubTypes.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

namespace poise::foxglove {

namespace {

using runtime::ConfigError;

std::int64_t clock_ns(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

template <typename T>
T bounded(const runtime::ComponentSpec& spec, const std::string& key, T fallback, T lo, T hi) {
  const T v = runtime::param<T>(spec, key, fallback);
  if (!(v >= lo && v <= hi)) {
    std::ostringstream os;
    os << spec.origin << ": parameter '" << key << "' of component '" << spec.name << "' must be in ["
       << lo << ", " << hi << "], got " << v;
    throw ConfigError(os.str());
  }
  return v;
}

/// How the bridge shows one DDS topic.
struct TopicState {
  std::string topic;
  std::string type;
  Channel raw;                       // raw.id = the channel id once advertised
  bool advertised = false;
  std::chrono::steady_clock::time_point last_alive;
  bool panel_tf = false;             // an estimate or vision pose: FrameTransform out
  std::string child;                 // its child frame
  double offset_x_m = 0.0;           // display offset (attitude only)
  std::uint32_t plot_channel = 0;    // poise.AttitudePlot channel (attitude topics), 0 none
};

class Bridge : public runtime::Component {
 public:
  Bridge(const runtime::ComponentSpec& spec, runtime::HostContext& host)
      : sensor_id_(spec.name),
        config_(parse_bridge_config(spec)),
        server_(config_.server),
        layout_(config_.frame_spacing_m),
        diagnostics_writer_(host.participant, host.topics.diagnostics, dds::QosKind::kEstimate) {
    schema::ObserverOptions o;
    o.domain = host.participant.domain();
    o.profile = host.participant_options.profile;
    o.qos_file = host.participant_options.qos_file;
    o.name = "poise:" + spec.name;
    observer_ = std::make_unique<schema::TopicObserver>(o);
    offset_ns_ = config_.realtime_stamps ? clock_ns(CLOCK_REALTIME) - clock_ns(CLOCK_MONOTONIC) : 0;
    std::fprintf(stderr, "poise: foxglove_bridge '%s': open ws://%s:%u in Foxglove or Lichtblick\n",
                 spec.name.c_str(), display_host().c_str(), static_cast<unsigned>(server_.port()));
  }

  ~Bridge() override {
    stop();
    observer_.reset();  // no callback after this
  }

  void start() override {
    if (running_.exchange(true)) {
      return;
    }
    server_.start();
    worker_ = std::thread([this] { run(); });
  }

  void stop() override {
    if (!running_.exchange(false)) {
      return;
    }
    {
      std::lock_guard<std::mutex> lock(wake_mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    if (worker_.joinable()) {
      worker_.join();
    }
    server_.stop();
  }

  [[nodiscard]] std::string status() const override {
    const ServerStats s = server_.stats();
    std::ostringstream os;
    os << "foxglove ws://" << display_host() << ":" << server_.port() << ": " << s.clients.size()
       << " client(s), " << s.channels << " channel(s), messages out " << s.sent << ", dropped "
       << s.dropped;
    for (const auto& c : s.clients) {
      if (c.dropped > 0) {
        os << " (client " << c.id << " " << c.remote << ": " << c.dropped << ")";
      }
    }
    os << ", requests refused " << s.errors << " (over budget " << s.throttled << "), idle closed "
       << s.idle_closed << ", malformed in " << malformed_.load()
       << ", panel skipped " << panel_skipped_.load();
    return os.str();
  }

 private:
  std::string display_host() const {
    return config_.server.address == "0.0.0.0" ? std::string("HOST") : config_.server.address;
  }

  /// Discovery (new topics, writers gone) and the diagnostics timer.
  void run() {
    auto next_diagnostics = std::chrono::steady_clock::now();
    while (true) {
      {
        std::unique_lock<std::mutex> lock(wake_mutex_);
        if (wake_.wait_for(lock, std::chrono::milliseconds(100), [this] { return stopping_; })) {
          return;
        }
      }
      try {
        discover();
      } catch (const std::exception& e) {
        warn_once("discover", std::string("foxglove_bridge: ") + e.what());
      }
      const auto now = std::chrono::steady_clock::now();
      if (now >= next_diagnostics) {
        publish_diagnostics();
        next_diagnostics = now + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                     std::chrono::duration<double>(config_.diagnostics_period_s));
      }
    }
  }

  void warn_once(const std::string& key, const std::string& text) {
    if (warned_.insert(key).second) {
      std::fprintf(stderr, "poise: warning: %s\n", text.c_str());
    }
  }

  bool wanted(const std::string& topic) const {
    if (config_.topics.empty()) {
      return !topic.empty() && topic[0] != '_';  // not middleware-internal topics
    }
    return std::find(config_.topics.begin(), config_.topics.end(), topic) != config_.topics.end();
  }

  void discover() {
    const auto now = std::chrono::steady_clock::now();
    std::set<std::string> alive;
    for (const auto& w : observer_->writers()) {
      if (!wanted(w.topic)) {
        continue;
      }
      alive.insert(w.topic);
      if (topics_.count(w.topic) != 0) {
        continue;
      }
      const schema::TypeTable& table = schema::TypeTable::builtin();
      if (table.find_struct(w.type) == nullptr) {
        warn_once("type:" + w.topic, "foxglove_bridge: topic '" + w.topic + "' has type " + w.type +
                                         " which is neither a poise nor a ROS 2 IDL type: not bridged");
        continue;
      }
      add_topic(w, table);
    }
    const auto hold = std::chrono::duration<double>(config_.unadvertise_after_s);
    for (auto& [name, t] : topics_) {
      if (alive.count(name) != 0) {
        t->last_alive = now;
        if (!t->advertised) {
          server_.add_channel(t->raw);  // the same id: same topic, encoding and schema
          t->advertised = true;
        }
      } else if (t->advertised && now - t->last_alive > hold) {
        server_.remove_channel(t->raw.id);
        t->advertised = false;
      }
    }
  }

  void add_topic(const schema::DiscoveredWriter& w, const schema::TypeTable& table) {
    auto t = std::make_unique<TopicState>();
    t->topic = w.topic;
    t->type = w.type;
    t->raw.topic = w.topic;
    t->raw.encoding = "cdr";
    t->raw.schema_name = w.type;
    t->raw.schema = table.flatten(w.type);
    t->raw.schema_encoding = "omgidl";
    t->raw.id = server_.add_channel(t->raw);
    t->advertised = true;
    t->last_alive = std::chrono::steady_clock::now();
    const bool attitude = w.type == "poise::msg::AttitudeEstimate";
    t->panel_tf = attitude || w.type == "poise::msg::PoseEstimate" || w.type == "poise::msg::VisionPose";
    if (t->panel_tf) {
      t->child = child_frame(w.topic);
      t->offset_x_m = attitude ? layout_.offset_m(t->child) : 0.0;
      if (tf_channel_ == 0) {
        tf_channel_ = server_.add_channel({0, "foxglove/tf", "json", kFrameTransformSchemaName,
                                           frame_transform_schema(), "jsonschema"});
      }
    }
    if (attitude) {
      t->plot_channel = server_.add_channel({0, "foxglove/attitude/" + t->child, "json",
                                             kAttitudePlotSchemaName, attitude_plot_schema(), "jsonschema"});
    }
    TopicState* state = t.get();
    topics_.emplace(w.topic, std::move(t));
    try {
      observer_->subscribe(
          w, &table,
          [this, state](const dds::RawSample& sample, const eprosima::fastdds::dds::SampleInfo&) {
            on_sample(*state, sample);
          },
          {}, [this](const dds::RawSample&, const eprosima::fastdds::dds::SampleInfo&, const std::string&) {
            malformed_.fetch_add(1);
          });
    } catch (const std::exception& e) {
      warn_once("subscribe:" + w.topic, "foxglove_bridge: cannot read '" + w.topic + "': " + e.what());
    }
  }

  /// A Fast DDS listener thread: forwards the payload; makes the panel messages when wanted.
  void on_sample(const TopicState& t, const dds::RawSample& sample) {
    const auto receive_ns = static_cast<std::uint64_t>(clock_ns(CLOCK_REALTIME));
    server_.publish(t.raw.id, receive_ns, sample.data.data(), sample.data.size());
    const bool tf = t.panel_tf && server_.subscribed(tf_channel_);
    const bool plot = t.plot_channel != 0 && server_.subscribed(t.plot_channel);
    if (!tf && !plot) {
      return;
    }
    schema::Value value;
    try {
      value = schema::decode(schema::TypeTable::builtin(), t.type, sample.data);
    } catch (const schema::DecodeError&) {
      panel_skipped_.fetch_add(1);
      return;
    }
    auto out = [&](std::uint32_t channel, const std::optional<std::string>& json) {
      if (!json) {
        panel_skipped_.fetch_add(1);
        return;
      }
      server_.publish(channel, receive_ns, reinterpret_cast<const std::uint8_t*>(json->data()), json->size());
    };
    if (tf) {
      out(tf_channel_, frame_transform_json(t.type, value, config_.world_frame, t.child, t.offset_x_m, offset_ns_));
    }
    if (plot) {
      out(t.plot_channel, attitude_plot_json(value, offset_ns_));
    }
  }

  void publish_diagnostics() {
    const ServerStats s = server_.stats();
    nodes::DiagnosticsReport report;
    report.stamp_ns = clock_ns(CLOCK_MONOTONIC);
    report.seq = diagnostics_seq_++;
    report.component = "foxglove_bridge";
    report.counters["clients"] = s.clients.size();
    report.counters["channels"] = s.channels;
    report.counters["connections"] = s.connections;
    report.counters["handshakes_refused"] = s.refused;
    report.counters["messages_out"] = s.sent;
    report.counters["messages_dropped"] = s.dropped;
    report.counters["requests_refused"] = s.errors;
    report.counters["requests_over_budget"] = s.throttled;
    report.counters["clients_idle_closed"] = s.idle_closed;
    report.counters["samples_malformed"] = malformed_.load();
    report.counters["panel_skipped"] = panel_skipped_.load();
    for (const auto& c : s.clients) {
      report.counters["client_" + std::to_string(c.id) + "_dropped"] = c.dropped;
      report.counters["client_" + std::to_string(c.id) + "_queued"] = c.queued;
    }
    diagnostics_writer_.write(nodes::to_diagnostics_msg(report, sensor_id_));
  }

  std::string sensor_id_;
  BridgeConfig config_;
  Server server_;
  FrameLayout layout_;  // discovery thread only
  std::int64_t offset_ns_ = 0;
  std::unique_ptr<schema::TopicObserver> observer_;
  std::map<std::string, std::unique_ptr<TopicState>> topics_;  // discovery thread only
  std::atomic<std::uint32_t> tf_channel_{0};
  std::set<std::string> warned_;
  std::atomic<std::uint64_t> malformed_{0};
  std::atomic<std::uint64_t> panel_skipped_{0};
  dds::Writer<msg::FilterDiagnosticsPubSubType> diagnostics_writer_;
  std::uint32_t diagnostics_seq_ = 0;
  std::atomic<bool> running_{false};
  std::mutex wake_mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::thread worker_;
};

}  // namespace

BridgeConfig parse_bridge_config(const runtime::ComponentSpec& spec) {
  runtime::check_known_params(spec, {"port", "address", "topics", "world_frame", "frame_spacing_m", "stamps",
                                     "max_clients", "queue_frames", "queue_bytes", "socket_buffer_bytes",
                                     "max_request_bytes", "max_requests_per_s", "idle_timeout_s",
                                     "unadvertise_after_s", "diagnostics_period_s"});
  BridgeConfig c;
  c.server.port = static_cast<std::uint16_t>(bounded<int>(spec, "port", c.server.port, 0, 65535));
  c.server.address = runtime::param<std::string>(spec, "address", c.server.address);
  c.server.name = "poise foxglove_bridge (" + spec.name + ")";
  c.topics = runtime::param<std::vector<std::string>>(spec, "topics", c.topics);
  c.world_frame = runtime::param<std::string>(spec, "world_frame", c.world_frame);
  if (c.world_frame.empty()) {
    throw ConfigError(spec.origin + ": parameter 'world_frame' of component '" + spec.name + "' is empty");
  }
  c.frame_spacing_m = bounded<double>(spec, "frame_spacing_m", c.frame_spacing_m, 0.0, 100.0);
  const std::string stamps = runtime::param<std::string>(spec, "stamps", "realtime");
  if (stamps != "realtime" && stamps != "sensor") {
    throw ConfigError(spec.origin + ": parameter 'stamps' of component '" + spec.name +
                      "' must be realtime or sensor, got '" + stamps + "'");
  }
  c.realtime_stamps = stamps == "realtime";
  c.server.max_clients = bounded<std::size_t>(spec, "max_clients", c.server.max_clients, 1, 1024);
  c.server.queue_frames = bounded<std::size_t>(spec, "queue_frames", c.server.queue_frames, 1, 1'000'000);
  c.server.queue_bytes = bounded<std::size_t>(spec, "queue_bytes", c.server.queue_bytes, 1024, 1u << 30);
  c.server.max_socket_buffer_bytes =
      bounded<std::size_t>(spec, "socket_buffer_bytes", c.server.max_socket_buffer_bytes, 1024, 1u << 30);
  c.server.max_request_bytes =
      bounded<std::size_t>(spec, "max_request_bytes", c.server.max_request_bytes, 256, 16u << 20);
  c.server.max_frame_bytes = std::max(c.server.max_frame_bytes, 4 * c.server.max_request_bytes);
  c.server.max_requests_per_s =
      bounded<double>(spec, "max_requests_per_s", c.server.max_requests_per_s, 1.0, 100000.0);
  c.server.idle_timeout_s = bounded<double>(spec, "idle_timeout_s", c.server.idle_timeout_s, 0.0, 86400.0);
  c.unadvertise_after_s = bounded<double>(spec, "unadvertise_after_s", c.unadvertise_after_s, 0.1, 3600.0);
  c.diagnostics_period_s = bounded<double>(spec, "diagnostics_period_s", c.diagnostics_period_s, 0.05, 3600.0);
  return c;
}

void register_foxglove_bridge(runtime::ComponentRegistry& registry) {
  runtime::ComponentType t{
      "foxglove_bridge",
      "Foxglove WebSocket server (foxglove.websocket.v1): every topic of the domain live in Foxglove or "
      "Lichtblick, raw CDR with its IDL schema, plus 3D frames and plots",
      [](const runtime::ComponentSpec& spec, runtime::HostContext& host) {
        try {
          return std::unique_ptr<runtime::Component>(std::make_unique<Bridge>(spec, host));
        } catch (const ServerError& e) {
          throw ConfigError(spec.origin + ": " + e.what());
        }
      }};
  t.command = "foxglove";
  t.command_options = {
      {"--port", "port", "INT", "TCP port to serve on, 0-65535 (0: any free port; default 8765)"},
      {"--address", "address", "ADDRESS",
       "Address to listen on (default 0.0.0.0: every interface; 127.0.0.1: this host only)"}};
  registry.add(std::move(t));
}

}  // namespace poise::foxglove

namespace poise::runtime {
void register_foxglove_bridge_component(ComponentRegistry& registry) { foxglove::register_foxglove_bridge(registry); }
}  // namespace poise::runtime
