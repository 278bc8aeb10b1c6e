#include "poise/nodes/imu_node.h"

#include "poise/dds/convert.h"

#include <chrono>
#include <ctime>
#include <sstream>

namespace poise::nodes {

int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

const std::vector<std::string>& NodeParams::keys() {
  static const std::vector<std::string> k{"diagnostics_every", "diagnostics_period_s",
                                          "input_deadline_s"};
  return k;
}

NodeParams node_params(const runtime::ComponentSpec& spec) {
  NodeParams p;
  p.diagnostics_every = runtime::param<int>(spec, "diagnostics_every", p.diagnostics_every);
  if (p.diagnostics_every < 1) {
    throw runtime::ConfigError(spec.origin + ": diagnostics_every must be >= 1");
  }
  p.diagnostics_period_s = runtime::param<double>(spec, "diagnostics_period_s", p.diagnostics_period_s);
  if (!(p.diagnostics_period_s >= 0.01 && p.diagnostics_period_s <= 3600.0)) {
    throw runtime::ConfigError(spec.origin + ": diagnostics_period_s must be in [0.01, 3600] s");
  }
  p.input_deadline_s = runtime::param<double>(spec, "input_deadline_s", p.input_deadline_s);
  if (!(p.input_deadline_s > 0.0 && p.input_deadline_s <= 3600.0)) {
    throw runtime::ConfigError(spec.origin + ": input_deadline_s must be in (0, 3600] s");
  }
  return p;
}

const std::vector<std::string>& north_keys() {
  static const std::vector<std::string> k{"declination_deg", "location", "date", "magnetic_model",
                                          "seed_field"};
  return k;
}

namespace {
std::string utc_today() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[16];
  std::strftime(buf, sizeof buf, "%Y-%m-%d", &tm);
  return buf;
}
}  // namespace

NorthReference north_reference(const runtime::ComponentSpec& spec) {
  NorthParams p;
  p.declination_deg = runtime::param<double>(spec, "declination_deg", p.declination_deg);
  p.date = runtime::param<std::string>(spec, "date", p.date);
  p.model_file = runtime::param<std::string>(spec, "magnetic_model", p.model_file);
  p.seed_field = runtime::param<bool>(spec, "seed_field", p.seed_field);
  const std::string where = spec.origin + ": component '" + spec.name + "': ";
  if (spec.params && spec.params["location"]) {
    const YAML::Node loc = spec.params["location"];
    if (!loc.IsMap()) {
      throw runtime::ConfigError(where + "location must be a mapping {lat_deg, lon_deg, alt_m}");
    }
    for (const auto& kv : loc) {
      const auto key = kv.first.as<std::string>();
      if (key != "lat_deg" && key != "lon_deg" && key != "alt_m") {
        throw runtime::ConfigError(where + "unknown key 'location." + key + "' (known: lat_deg, lon_deg, alt_m)");
      }
    }
    if (!loc["lat_deg"] || !loc["lon_deg"]) {
      throw runtime::ConfigError(where + "location needs lat_deg and lon_deg (alt_m optional, default 0)");
    }
    try {
      p.location.lat_deg = loc["lat_deg"].as<double>();
      p.location.lon_deg = loc["lon_deg"].as<double>();
      p.location.alt_m = loc["alt_m"] ? loc["alt_m"].as<double>() : 0.0;
    } catch (const YAML::Exception&) {
      throw runtime::ConfigError(where + "location: lat_deg, lon_deg and alt_m must be numbers (deg, deg, m)");
    }
    p.has_location = true;
  } else if (!p.date.empty() || !p.model_file.empty()) {
    throw runtime::ConfigError(where + "date and magnetic_model need a location");
  }
  try {
    return resolve_north(p, utc_today());
  } catch (const std::exception& e) {
    throw runtime::ConfigError(where + e.what());
  }
}

ImuEstimatorNode::ImuEstimatorNode(const runtime::ComponentSpec& spec, runtime::HostContext& host,
                                   std::string component)
    : host_(host),
      sensor_id_(spec.name),
      component_(std::move(component)),
      params_(node_params(spec)),
      inputs_(static_cast<int64_t>(params_.input_deadline_s * 1e9), monotonic_ns()) {
  diagnostics_writer_ = std::make_unique<dds::Writer<msg::FilterDiagnosticsPubSubType>>(
      host.participant, host.topics.diagnostics, dds::QosKind::kEstimate);
}

ImuEstimatorNode::~ImuEstimatorNode() { ImuEstimatorNode::stop(); }

void ImuEstimatorNode::start() {
  running_.store(true);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    inputs_.expect(host_.topics.imu);
  }
  if (!imu_reader_) {
    imu_reader_ = std::make_unique<dds::Reader<msg::ImuSamplePubSubType>>(
        host_.participant, host_.topics.imu, dds::QosKind::kSensor,
        [this](const msg::ImuSample& m, const auto& info) { on_imu(m, info); }, &malformed_);
  }
  if (!timer_.joinable()) {
    {
      std::lock_guard<std::mutex> lock(timer_mutex_);
      timer_stop_ = false;
    }
    timer_ = std::thread([this] { run_timer(); });
  }
}

void ImuEstimatorNode::stop() {
  running_.store(false);
  imu_reader_.reset();  // no callback runs after this returns
  {
    std::lock_guard<std::mutex> lock(timer_mutex_);
    timer_stop_ = true;
  }
  timer_cv_.notify_all();
  if (timer_.joinable()) {
    timer_.join();
  }
}

void ImuEstimatorNode::run_timer() {
  const auto period = std::chrono::duration<double>(params_.diagnostics_period_s);
  std::unique_lock<std::mutex> timer_lock(timer_mutex_);
  while (!timer_cv_.wait_for(timer_lock, period, [this] { return timer_stop_; })) {
    std::lock_guard<std::mutex> lock(mutex_);
    const int64_t now = monotonic_ns();
    publish_diagnostics(now, last_seq_, now);
  }
}

void ImuEstimatorNode::track_input(const std::string& topic, const std::string& source, uint32_t seq,
                                   const eprosima::fastdds::dds::SampleInfo& info) {
  inputs_.on_sample(topic, source, seq, dds::writer_key(info), monotonic_ns());
}

void ImuEstimatorNode::on_imu(const msg::ImuSample& m, const eprosima::fastdds::dds::SampleInfo& info) {
  if (!running_.load()) {
    return;
  }
  received_.fetch_add(1);
  const ImuSample sample = dds::from_msg(m);
  std::lock_guard<std::mutex> lock(mutex_);
  track_input(host_.topics.imu, m.sensor_id().to_string(), m.header().seq(), info);
  last_seq_ = sample.seq;
  if (!step(sample)) {
    rejected_.fetch_add(1);
  } else if (publish_estimate(sample)) {
    published_.fetch_add(1);
    last_latency_ns_.store(monotonic_ns() - sample.stamp_ns);
  }
  if (++since_diagnostics_ < static_cast<uint64_t>(params_.diagnostics_every)) {
    return;
  }
  since_diagnostics_ = 0;
  core_report_ = DiagnosticsReport{};
  diagnostics(core_report_);
  publish_diagnostics(sample.stamp_ns, sample.seq, monotonic_ns());
}

void ImuEstimatorNode::publish_diagnostics(int64_t stamp_ns, uint32_t seq, int64_t now_ns) {
  DiagnosticsReport diag = core_report_;
  diag.stamp_ns = stamp_ns;
  diag.seq = seq;
  diag.component = component_;
  inputs_.report(now_ns, diag);
  diag.metrics.push_back({"latency", static_cast<double>(last_latency_ns_.load()) * 1e-6, "ms"});
  diag.counters["samples_received"] = received_.load();
  diag.counters["samples_rejected"] = rejected_.load();
  diag.counters["samples_malformed"] = malformed_.load();
  diag.counters["estimates_published"] = published_.load();
  diagnostics_writer_->write(to_diagnostics_msg(diag, sensor_id_));
}

std::string ImuEstimatorNode::status() const {
  std::ostringstream os;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::string silence = describe_silence(inputs_.silent(monotonic_ns()));
    if (!silence.empty()) {
      os << silence << "; ";
    }
    os << "imu lost " << inputs_.totals(host_.topics.imu).lost << ", ";
  }
  os << "imu in " << received_.load() << ", estimates out " << published_.load() << ", rejected "
     << rejected_.load() << ", malformed " << malformed_.load()
     << ", last latency " << static_cast<double>(last_latency_ns_.load()) * 1e-3
     << " us";
  return os.str();
}

ImuAttitudeNode::ImuAttitudeNode(const runtime::ComponentSpec& spec, runtime::HostContext& host,
                                 std::string filter_id)
    : ImuEstimatorNode(spec, host, filter_id),
      north_(north_reference(spec)),
      attitude_writer_(host.participant, host.topics.attitude(filter_id), dds::QosKind::kEstimate) {}

bool ImuAttitudeNode::publish_estimate(const ImuSample& sample) {
  report_ = AttitudeReport{};
  if (!attitude(report_)) {
    return false;
  }
  report_.stamp_ns = sample.stamp_ns;
  report_.seq = sample.seq;
  report_.frame_id = north_.frame_id();
  if (north_.true_north) {  // no-op without a declination: outputs unchanged bit for bit
    report_.q_world_body = north_.to_true(report_.q_world_body);
    report_.covariance = north_.to_true(report_.covariance);
    report_.ext_accel_world_mps2 = north_.to_true(report_.ext_accel_world_mps2);
    report_.mag_disturbance_world_ut = north_.to_true(report_.mag_disturbance_world_ut);
  }
  attitude_writer_.write(to_attitude_msg(report_, sensor_id(), component()));
  return true;
}

}  // namespace poise::nodes
