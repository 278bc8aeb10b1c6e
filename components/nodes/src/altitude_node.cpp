// Component `altitude`: height and vertical velocity from IMU + barometer (paper 003) on DDS.
//   in:  imu (ImuSample with pressure)     out: altitude (AltitudeEstimate), diagnostics
//   params: filter_file (YAML of AltitudeParams), method (overrides the file: pi_cf_zupt, cf_zupt,
//           pi_cf, two_step_kf), relative_to_start (report heights above the start: the mean
//           barometric height over the first second; nothing is published during that second;
//           default false: heights above the reference pressure level),
//           diagnostics_every
#include "poise/altitude/altitude_filter.h"
#include "poise/dds/convert.h"
#include "poise/nodes/imu_node.h"
#include "poise/nodes/register.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include <atomic>
#include <optional>
#include <sstream>

namespace poise::nodes {
namespace {

AltitudeParams load_params(const runtime::ComponentSpec& spec) {
  std::vector<std::string> known = NodeParams::keys();
  known.insert(known.end(), {"filter_file", "method", "relative_to_start"});
  runtime::check_known_params(spec, known);
  AltitudeParams p;
  const auto file = runtime::param<std::string>(spec, "filter_file", "");
  try {
    if (!file.empty()) {
      p = load_altitude_params(file);
    }
  } catch (const std::exception& e) {
    throw runtime::ConfigError(spec.origin + ": " + e.what());
  }
  const auto method = runtime::param<std::string>(spec, "method", "");
  if (!method.empty() && !parse_altitude_method(method, p.method)) {
    throw runtime::ConfigError(spec.origin + ": unknown method '" + method +
                               "' (pi_cf_zupt, cf_zupt, pi_cf, two_step_kf)");
  }
  return p;
}

class AltitudeNode : public runtime::Component {
 public:
  AltitudeNode(const runtime::ComponentSpec& spec, runtime::HostContext& host)
      : host_(host),
        sensor_id_(spec.name),
        node_(node_params(spec)),
        relative_(runtime::param<bool>(spec, "relative_to_start", false)),
        filter_(load_params(spec)),
        writer_(host.participant, host.topics.altitude, dds::QosKind::kEstimate),
        diagnostics_(host.participant, host.topics.diagnostics, dds::QosKind::kEstimate) {}
  ~AltitudeNode() override { AltitudeNode::stop(); }

  void start() override {
    if (!reader_) {
      reader_ = std::make_unique<dds::Reader<msg::ImuSamplePubSubType>>(
          host_.participant, host_.topics.imu, dds::QosKind::kSensor,
          [this](const msg::ImuSample& m, const auto&) { on_imu(m); });
    }
  }
  void stop() override { reader_.reset(); }
  [[nodiscard]] std::string status() const override {
    std::ostringstream os;
    os << "imu in " << received_.load() << ", estimates out " << published_.load() << ", rejected "
       << filter_rejected_.load();
    return os.str();
  }

 private:
  void on_imu(const msg::ImuSample& m) {
    received_.fetch_add(1);
    const ImuSample sample = dds::from_msg(m);
    filter_.update(sample);
    filter_rejected_.store(filter_.rejects().total());
    const AltitudeEstimate& e = filter_.estimate();
    if (!e.valid) {
      return;
    }
    const std::optional<double> zero = relative_ ? start_zero_.add(e) : std::optional<double>(0.0);
    if (!zero) {
      return;  // relative_to_start: the zero is still being averaged
    }
    const double offset = *zero;
    msg::AltitudeEstimate out;
    out.header(dds::make_header(sample.stamp_ns, sample.seq, "world"));
    out.sensor_id(sensor_id_);
    out.filter_id("altitude");
    out.method(to_string(filter_.params().method));
    out.height_m(e.height_m - offset);
    out.vertical_velocity_mps(e.vertical_velocity_mps);
    out.vertical_accel_mps2(e.vertical_accel_mps2);
    out.stationary(e.stationary);
    out.baro_valid(e.baro_fresh);
    out.baro_height_m(e.baro_height_m - offset);
    out.reference_pressure_pa(filter_.params().reference_pressure_pa);
    writer_.write(out);
    published_.fetch_add(1);
    if (++since_diagnostics_ >= static_cast<uint64_t>(node_.diagnostics_every)) {
      since_diagnostics_ = 0;
      const AltitudeRejects& r = filter_.rejects();
      DiagnosticsReport d;
      d.stamp_ns = sample.stamp_ns;
      d.seq = sample.seq;
      d.component = "altitude";
      SourceReport baro;
      baro.source = "baro";
      baro.fresh = sample.has_pressure;
      baro.fused = e.baro_fresh;
      baro.reason = e.baro_fresh ? "" : (sample.has_pressure ? "rejected_pressure" : "no_sample");
      SourceReport zupt;
      zupt.source = "zupt";
      zupt.fresh = true;
      zupt.fused = e.zupt_applied;
      zupt.reason = e.zupt_applied ? "" : "moving";
      d.sources = {baro, zupt};
      d.counters = {{"rejected_non_finite_imu", r.non_finite_imu},
                    {"rejected_non_monotonic_stamp", r.non_monotonic_stamp},
                    {"time_gap", r.dt_gap},
                    {"rejected_bad_pressure", r.bad_pressure}};
      d.metrics = {{"latency", static_cast<double>(monotonic_ns() - sample.stamp_ns) * 1e-6, "ms"}};
      diagnostics_.write(to_diagnostics_msg(d, sensor_id_));
    }
  }

  runtime::HostContext& host_;
  std::string sensor_id_;
  NodeParams node_;
  bool relative_;
  AltitudeFilter filter_;
  StartZero start_zero_;
  dds::Writer<msg::AltitudeEstimatePubSubType> writer_;
  dds::Writer<msg::FilterDiagnosticsPubSubType> diagnostics_;
  std::unique_ptr<dds::Reader<msg::ImuSamplePubSubType>> reader_;
  std::atomic<uint64_t> received_{0};
  std::atomic<uint64_t> published_{0};
  std::atomic<uint64_t> filter_rejected_{0};
  uint64_t since_diagnostics_ = 0;
};

}  // namespace

void register_altitude_node(runtime::ComponentRegistry& registry) {
  registry.add({"altitude", "Height and vertical velocity from IMU + barometer (PI complementary filter + ZUPT)",
                [](const runtime::ComponentSpec& spec, runtime::HostContext& host) {
                  return std::make_unique<AltitudeNode>(spec, host);
                }});
}

}  // namespace poise::nodes
