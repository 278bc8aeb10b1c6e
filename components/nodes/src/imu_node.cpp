#include "poise/nodes/imu_node.h"

#include "poise/dds/convert.h"

#include <ctime>
#include <sstream>

namespace poise::nodes {

int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

const std::vector<std::string>& NodeParams::keys() {
  static const std::vector<std::string> k{"diagnostics_every"};
  return k;
}

NodeParams node_params(const runtime::ComponentSpec& spec) {
  NodeParams p;
  p.diagnostics_every = runtime::param<int>(spec, "diagnostics_every", p.diagnostics_every);
  if (p.diagnostics_every < 1) {
    throw runtime::ConfigError(spec.origin + ": diagnostics_every must be >= 1");
  }
  return p;
}

ImuAttitudeNode::ImuAttitudeNode(const runtime::ComponentSpec& spec, runtime::HostContext& host,
                                 std::string filter_id)
    : host_(host), sensor_id_(spec.name), filter_id_(std::move(filter_id)), params_(node_params(spec)) {
  attitude_writer_ = std::make_unique<dds::Writer<msg::AttitudeEstimatePubSubType>>(
      host.participant, host.topics.attitude(filter_id_), dds::QosKind::kEstimate);
  diagnostics_writer_ = std::make_unique<dds::Writer<msg::FilterDiagnosticsPubSubType>>(
      host.participant, host.topics.diagnostics, dds::QosKind::kEstimate);
}

ImuAttitudeNode::~ImuAttitudeNode() { ImuAttitudeNode::stop(); }

void ImuAttitudeNode::start() {
  running_.store(true);
  if (!imu_reader_) {
    imu_reader_ = std::make_unique<dds::Reader<msg::ImuSamplePubSubType>>(
        host_.participant, host_.topics.imu, dds::QosKind::kSensor,
        [this](const msg::ImuSample& m, const auto& /*info*/) { on_imu(m); });
  }
}

void ImuAttitudeNode::stop() {
  running_.store(false);
  imu_reader_.reset();  // no callback runs after this returns
}

void ImuAttitudeNode::on_imu(const msg::ImuSample& m) {
  if (!running_.load()) {
    return;
  }
  received_.fetch_add(1);
  const ImuSample sample = dds::from_msg(m);
  AttitudeReport report;
  DiagnosticsReport diag;
  std::lock_guard<std::mutex> lock(mutex_);
  if (!step(sample, report, diag)) {
    rejected_.fetch_add(1);
    return;
  }
  const bool with_diagnostics = ++since_diagnostics_ >= static_cast<uint64_t>(params_.diagnostics_every);
  publish(report, diag, with_diagnostics);
}

void ImuAttitudeNode::publish(const AttitudeReport& report, DiagnosticsReport& diag, bool with_diagnostics) {
  attitude_writer_->write(to_attitude_msg(report, sensor_id_, filter_id_));
  published_.fetch_add(1);
  const int64_t latency = monotonic_ns() - report.stamp_ns;
  last_latency_ns_.store(latency);
  if (with_diagnostics) {
    since_diagnostics_ = 0;
    diag.stamp_ns = report.stamp_ns;
    diag.seq = report.seq;
    diag.component = filter_id_;
    diag.metrics.push_back({"latency", static_cast<double>(latency) * 1e-6, "ms"});
    diag.counters["samples_received"] = received_.load();
    diag.counters["estimates_published"] = published_.load();
    diagnostics_writer_->write(to_diagnostics_msg(diag, sensor_id_));
  }
}

std::string ImuAttitudeNode::status() const {
  std::ostringstream os;
  os << "imu in " << received_.load() << ", estimates out " << published_.load() << ", rejected "
     << rejected_.load() << ", last latency " << static_cast<double>(last_latency_ns_.load()) * 1e-3
     << " us";
  return os.str();
}

}  // namespace poise::nodes
