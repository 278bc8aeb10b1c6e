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

ImuEstimatorNode::ImuEstimatorNode(const runtime::ComponentSpec& spec, runtime::HostContext& host,
                                   std::string component)
    : host_(host), sensor_id_(spec.name), component_(std::move(component)), params_(node_params(spec)) {
  diagnostics_writer_ = std::make_unique<dds::Writer<msg::FilterDiagnosticsPubSubType>>(
      host.participant, host.topics.diagnostics, dds::QosKind::kEstimate);
}

ImuEstimatorNode::~ImuEstimatorNode() { ImuEstimatorNode::stop(); }

void ImuEstimatorNode::start() {
  running_.store(true);
  if (!imu_reader_) {
    imu_reader_ = std::make_unique<dds::Reader<msg::ImuSamplePubSubType>>(
        host_.participant, host_.topics.imu, dds::QosKind::kSensor,
        [this](const msg::ImuSample& m, const auto& /*info*/) { on_imu(m); }, &malformed_);
  }
}

void ImuEstimatorNode::stop() {
  running_.store(false);
  imu_reader_.reset();  // no callback runs after this returns
}

void ImuEstimatorNode::on_imu(const msg::ImuSample& m) {
  if (!running_.load()) {
    return;
  }
  received_.fetch_add(1);
  const ImuSample sample = dds::from_msg(m);
  std::lock_guard<std::mutex> lock(mutex_);
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
  DiagnosticsReport diag;
  diagnostics(diag);
  diag.stamp_ns = sample.stamp_ns;
  diag.seq = sample.seq;
  diag.component = component_;
  diag.metrics.push_back({"latency", static_cast<double>(last_latency_ns_.load()) * 1e-6, "ms"});
  diag.counters["samples_received"] = received_.load();
  diag.counters["samples_rejected"] = rejected_.load();
  diag.counters["samples_malformed"] = malformed_.load();
  diag.counters["estimates_published"] = published_.load();
  diagnostics_writer_->write(to_diagnostics_msg(diag, sensor_id_));
}

std::string ImuEstimatorNode::status() const {
  std::ostringstream os;
  os << "imu in " << received_.load() << ", estimates out " << published_.load() << ", rejected "
     << rejected_.load() << ", malformed " << malformed_.load()
     << ", last latency " << static_cast<double>(last_latency_ns_.load()) * 1e-3
     << " us";
  return os.str();
}

ImuAttitudeNode::ImuAttitudeNode(const runtime::ComponentSpec& spec, runtime::HostContext& host,
                                 std::string filter_id)
    : ImuEstimatorNode(spec, host, filter_id),
      attitude_writer_(host.participant, host.topics.attitude(filter_id), dds::QosKind::kEstimate) {}

bool ImuAttitudeNode::publish_estimate(const ImuSample& sample) {
  report_ = AttitudeReport{};
  if (!attitude(report_)) {
    return false;
  }
  report_.stamp_ns = sample.stamp_ns;
  report_.seq = sample.seq;
  attitude_writer_.write(to_attitude_msg(report_, sensor_id(), component()));
  return true;
}

}  // namespace poise::nodes
