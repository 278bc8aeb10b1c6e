#include "poise/imu/imu_driver_node.h"

#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "poise/dds/convert.h"
#include "poise/runtime/shipped.h"

namespace poise::imu {
namespace {
// The driver configuration's sections (given inline instead of config_file) and the node's own keys.
const std::vector<std::string> kDriverSections{"serial", "protocol", "limits", "raw", "clock", "calibration"};
const std::vector<std::string> kNodeKeys{"port",     "baud",          "config_file", "diagnostics_period_s",
                                         "reliable", "publish_queue", "max_age_s"};
}  // namespace

ImuNodeOptions imu_node_options(const runtime::ComponentSpec& spec) {
  std::vector<std::string> known = kNodeKeys;
  known.insert(known.end(), kDriverSections.begin(), kDriverSections.end());
  runtime::check_known_params(spec, known);
  ImuNodeOptions o;
  YAML::Node inline_driver(YAML::NodeType::Map);
  bool has_inline = false;
  for (const auto& section : kDriverSections) {
    if (spec.params && spec.params.IsMap() && spec.params[section]) {
      inline_driver[section] = spec.params[section];
      has_inline = true;
    }
  }
  o.port = runtime::param<std::string>(spec, "port", "");
  if (o.port.empty()) {
    throw runtime::ConfigError(spec.origin + ": imu_driver needs 'port' (e.g. /dev/ttyACM0, or "
                                             "the --link of `poise sim-imu`)");
  }
  const auto config_file = runtime::param<std::string>(spec, "config_file", "");
  try {
    if (!config_file.empty()) {
      if (has_inline) {
        throw runtime::ConfigError(spec.origin + ": give either config_file or inline driver "
                                                 "sections, not both");
      }
      std::error_code ec;
      if (!std::filesystem::exists(config_file, ec)) {
        throw runtime::ConfigError(spec.origin + ": config_file " + config_file +
                                   " does not exist (start from " +
                                   runtime::shipped_file_hint("drivers/imu.yaml") +
                                   ", or run `poise calibrate imu`)");
      }
      o.config = load_driver_config(config_file);
    } else if (has_inline) {
      o.config = parse_driver_config(YAML::Dump(inline_driver), spec.origin);
    }
  } catch (const ConfigError& e) {
    throw runtime::ConfigError(e.what());
  }
  const int baud = runtime::param<int>(spec, "baud", o.config.serial.baud);
  if (!is_supported_baud(baud)) {
    throw runtime::ConfigError(spec.origin + ": baud " + std::to_string(baud) +
                               " is not supported (9600, 19200, 38400, 57600, 115200, 230400, "
                               "460800, 500000, 576000, 921600, 1000000)");
  }
  o.config.serial.baud = baud;
  o.diagnostics_period_s = runtime::param<double>(spec, "diagnostics_period_s", o.diagnostics_period_s);
  if (!(o.diagnostics_period_s > 0.0 && o.diagnostics_period_s <= 3600.0)) {
    throw runtime::ConfigError(spec.origin + ": diagnostics_period_s must be in (0, 3600]");
  }
  o.reliable = runtime::param<bool>(spec, "reliable", o.reliable);
  const int queue = runtime::param<int>(spec, "publish_queue", static_cast<int>(o.publish_queue));
  if (queue < 1 || queue > 100000) {
    throw runtime::ConfigError(spec.origin + ": publish_queue must be in [1, 100000] samples");
  }
  o.publish_queue = static_cast<std::size_t>(queue);
  o.max_age_s = runtime::param<double>(spec, "max_age_s", o.max_age_s);
  if (!(o.max_age_s >= 0.0 && o.max_age_s <= 3600.0)) {
    throw runtime::ConfigError(spec.origin + ": max_age_s must be in [0, 3600] s (0: no limit)");
  }
  return o;
}

msg::ImuSensorInfo to_info_msg(const SensorDelay& delay, const std::string& sensor_id, int64_t stamp_ns) {
  msg::ImuSensorInfo m;
  msg::Header h;
  h.stamp_ns(stamp_ns);
  h.frame_id("body");
  m.header(h);
  m.sensor_id(sensor_id);
  m.chip(delay.chip);
  m.filter_setting(delay.setting);
  m.accel_delay_s(delay.accel_delay_s);
  m.gyro_delay_s(delay.gyro_delay_s);
  m.origin(delay.origin);
  return m;
}

nodes::DiagnosticsReport driver_diagnostics(const DriverStats& st, const RateLatencyMeter::Summary& rate,
                                            bool connected, uint64_t connects, int64_t stamp_ns,
                                            uint32_t seq) {
  nodes::DiagnosticsReport r;
  r.stamp_ns = stamp_ns;
  r.seq = seq;
  r.component = "imu_driver";
  for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
    r.counters[std::string("rejected_") + to_string(static_cast<RejectReason>(i))] = st.rejects[i];
  }
  r.counters["rejected_total"] = st.rejected_total();
  r.counters["samples"] = st.samples;
  r.counters["lines"] = st.lines;
  r.counters["bytes"] = st.bytes;
  r.counters["info_lines"] = st.info_lines;
  r.counters["samples_without_mag"] = st.samples_without_mag;
  r.counters["dropped_seq_gap"] = st.seq_gap_drops;
  r.counters["sensor_restarts"] = st.sensor_restarts;
  r.counters["disconnects"] = st.disconnects;
  r.counters["connects"] = connects;
  r.counters["clock_resets"] = st.clock_resets;
  r.counters["clock_reanchors"] = st.clock_reanchors;
  r.counters["sensor_info_lines"] = st.sensor_info_lines;
  r.metrics.push_back({"rate", rate.rate_hz, "Hz"});
  r.metrics.push_back({"latency_p50", rate.latency_p50_ms, "ms"});
  r.metrics.push_back({"latency_p99", rate.latency_p99_ms, "ms"});
  r.metrics.push_back({"latency_max", rate.latency_max_ms, "ms"});
  r.metrics.push_back({"clock_offset", static_cast<double>(st.clock_offset_ns) * 1e-9, "s"});
  r.metrics.push_back({"clock_drift", st.clock_drift_ppm, "ppm"});
  r.metrics.push_back({"connected", connected ? 1.0 : 0.0, "bool"});
  return r;
}

ImuDriverNode::ImuDriverNode(const ImuNodeOptions& options, const std::string& sensor_id,
                             runtime::HostContext& host)
    : options_(options),
      sensor_id_(dds::checked_sensor_id(sensor_id, "imu driver")),
      host_(host),
      imu_writer_(host.participant, host.topics.imu,
                  options.reliable ? dds::QosKind::kEstimate : dds::QosKind::kSensor),
      diag_writer_(host.participant, host.topics.diagnostics),
      info_writer_(host.participant, host.topics.imu_info, dds::QosKind::kStatic),
      driver_(options.config.params, options.config.calibration,
              [this](const ImuSample& s, const SampleInfo& i) { on_sample(s, i); }),
      reader_(ReaderOptions{options.port, options.config.serial},
              driver_, [this](const std::string& m) {
                if (options_.log_to_stderr) {
                  std::fprintf(stderr, "imu_driver %s: %s\n", sensor_id_.c_str(), m.c_str());
                }
              }),
      imu_queue_({options.publish_queue, static_cast<int64_t>(options.max_age_s * 1e9)},
                 [this](const msg::ImuSample& m) { return imu_writer_.write(m); },
                 monotonic_now_ns),
      diag_queue_({4, 0}, [this](const msg::FilterDiagnostics& m) { return diag_writer_.write(m); },
                  monotonic_now_ns),
      info_queue_({4, 0}, [this](const msg::ImuSensorInfo& m) { return info_writer_.write(m); },
                  monotonic_now_ns) {
  driver_.set_delay_sink([this](const SensorDelay& d) { on_delay(d); });
  driver_.set_info_problem_sink([this](const std::string& m) {
    if (options_.log_to_stderr) {
      std::fprintf(stderr, "imu_driver %s: refused: %s\n", sensor_id_.c_str(), m.c_str());
    }
  });
}

void ImuDriverNode::on_delay(const SensorDelay& delay) {
  const int64_t now = monotonic_now_ns();
  if (options_.log_to_stderr) {
    std::fprintf(stderr, "imu_driver %s: sensor delay %s; published on %s\n", sensor_id_.c_str(),
                 delay.describe().c_str(), host_.topics.imu_info.c_str());
  }
  info_queue_.push(to_info_msg(delay, sensor_id_, now), now);
}

ImuDriverNode::~ImuDriverNode() { stop(); }

void ImuDriverNode::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  {
    std::lock_guard<std::mutex> lock(status_mutex_);
    final_.clear();  // started again: the running line
  }
  thread_ = std::thread([this] {
    reader_.run([this] { return stop_.load(); }, [this](int64_t now) { on_tick(now); });
  });
}

void ImuDriverNode::stop() {
  stop_.store(true);
  const bool was_running = thread_.joinable();
  if (thread_.joinable()) thread_.join();
  imu_queue_.stop();
  diag_queue_.stop();
  info_queue_.stop();
  if (was_running) {  // the reading thread has ended: the counts are final
    const std::string line = final_counts(driver_.stats(), imu_queue_.stats());
    std::lock_guard<std::mutex> lock(status_mutex_);
    final_ = line;
  }
}

std::string final_counts(const DriverStats& st, const dds::PublishQueue<msg::ImuSample>::Stats& q) {
  std::ostringstream os;
  os << "final: " << st.samples << " samples read (" << st.lines << " lines, " << st.bytes << " bytes), "
     << q.written << " published, " << st.rejected_total() << " rejected";
  const char* sep = ": ";
  for (std::size_t r = 0; r < kRejectReasonCount; ++r) {
    if (st.rejects[r] != 0) {
      os << sep << to_string(static_cast<RejectReason>(r)) << " " << st.rejects[r];
      sep = ", ";
    }
  }
  os << "; " << st.seq_gap_drops << " lost (seq gaps); dropped " << q.dropped_stale << " stale, " << q.dropped_full
     << " queue full, " << q.dropped_at_stop << " at stop, " << q.write_failed << " write failures; "
     << st.disconnects << " disconnects";
  if (const std::string clock = clock_ratio_problem(st); !clock.empty()) {
    os << "; " << clock;
  }
  return os.str();
}

void ImuDriverNode::on_sample(const ImuSample& sample, const SampleInfo& info) {
  meter_.add(sample.stamp_ns, info.arrival_ns);
  last_stamp_ns_ = sample.stamp_ns;
  imu_queue_.push(dds::to_msg(sample, sensor_id_), sample.stamp_ns);  // never blocks
}

void ImuDriverNode::on_tick(int64_t now_ns) {
  {  // the counts as of now, for status() (the reading thread alone touches driver_)
    std::lock_guard<std::mutex> lock(status_mutex_);
    status_stats_ = driver_.stats();
    status_connected_ = reader_.connected();
    status_ticked_ = true;
  }
  if (now_ns < next_diag_ns_) return;
  next_diag_ns_ = now_ns + static_cast<int64_t>(options_.diagnostics_period_s * 1e9);
  const DriverStats& st = driver_.stats();
  const auto summary = meter_.summarize(now_ns);
  nodes::DiagnosticsReport report = driver_diagnostics(
      st, summary, reader_.connected(), reader_.connects(), last_stamp_ns_ != 0 ? last_stamp_ns_ : now_ns,
      diag_seq_++);
  const auto q = imu_queue_.stats();
  report.counters["published"] = q.written;
  report.counters["dds_write_failures"] = q.write_failed;
  report.counters["dropped_queue_full"] = q.dropped_full;
  report.counters["dropped_stale"] = q.dropped_stale;
  report.counters["dropped_at_stop"] = q.dropped_at_stop;
  report.counters["publish_queue_pending"] = q.pending;
  report.counters["publish_queue_high_water"] = q.high_water;
  report.counters["slow_writes"] = q.slow_writes;
  report.metrics.push_back({"longest_write", static_cast<double>(q.longest_write_ns) * 1e-6, "ms"});
  report.metrics.push_back({"clock_ratio", st.clock_ratio, "ratio"});  // sensor s per host s
  diag_queue_.push(nodes::to_diagnostics_msg(report, sensor_id_), now_ns);
  {
    std::lock_guard<std::mutex> lock(status_mutex_);
    status_rate_ = summary;
  }
  const std::string clock = clock_ratio_problem(st);
  // The sensor clock does not keep the host's pace (t_us in the wrong unit): said once, by name,
  // instead of a silent stream of stale drops (issue 33).
  if (!clock.empty() && !warned_clock_ && options_.log_to_stderr) {
    warned_clock_ = true;
    std::fprintf(stderr, "imu_driver %s: %s\n", sensor_id_.c_str(), clock.c_str());
  }
  // Bytes arriving without a single valid line: most likely the wrong baud rate.
  if (reader_.connected() && st.samples == 0 && st.bytes > 2000 && warned_no_valid_at_bytes_ == 0) {
    warned_no_valid_at_bytes_ = st.bytes;
    if (options_.log_to_stderr) {
      std::fprintf(stderr,
                   "imu_driver %s: %" PRIu64 " bytes received but no valid line: check that the "
                   "baud rate (%d) matches the firmware and that it prints the poise protocol "
                   "(docs/SERIAL_PROTOCOL.md)\n",
                   sensor_id_.c_str(), st.bytes, options_.config.serial.baud);
    }
  }
}

std::string status_line(const DriverStats& st, const RateLatencyMeter::Summary& rate,
                        const dds::PublishQueue<msg::ImuSample>::Stats& q, bool connected) {
  char line[640];
  std::snprintf(line, sizeof line,
                "%s, %.1f Hz, %" PRIu64 " lines, %" PRIu64 " samples, %" PRIu64 " rejected, %" PRIu64
                " lost (seq gaps), %" PRIu64 " published, dropped %" PRIu64 " stale %" PRIu64
                " queue full, longest write %.1f ms, latency p50 %.2f ms p99 %.2f ms, clock offset "
                "%.6f s drift %.0f ppm",
                connected ? "connected" : "waiting for port", rate.rate_hz, st.lines, st.samples,
                st.rejected_total(), st.seq_gap_drops, q.written, q.dropped_stale, q.dropped_full,
                static_cast<double>(q.longest_write_ns) * 1e-6, rate.latency_p50_ms, rate.latency_p99_ms,
                static_cast<double>(st.clock_offset_ns) * 1e-9, st.clock_drift_ppm);
  const std::string clock = clock_ratio_problem(st);
  return clock.empty() ? std::string(line) : std::string(line) + "; " + clock;
}

std::string ImuDriverNode::status() const {
  const auto q = imu_queue_.stats();  // its own lock, current
  std::lock_guard<std::mutex> lock(status_mutex_);
  if (!final_.empty()) {
    return final_;
  }
  if (!status_ticked_) {
    return "starting";
  }
  return status_line(status_stats_, status_rate_, q, status_connected_);
}

}  // namespace poise::imu

namespace poise::runtime {
void register_imu_driver(ComponentRegistry& registry) {
  ComponentType t;
  t.name = "imu_driver";
  t.description = "Serial IMU driver: port -> calibrated ImuSample on `imu` + diagnostics";
  t.standalone_command = false;  // `poise imu` is its dedicated command
  t.create = [](const ComponentSpec& spec, HostContext& host) -> std::unique_ptr<Component> {
    return std::make_unique<imu::ImuDriverNode>(imu::imu_node_options(spec), spec.name, host);
  };
  registry.add(std::move(t));
}
}  // namespace poise::runtime
