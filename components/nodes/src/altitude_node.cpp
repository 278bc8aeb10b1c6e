// Component `altitude`: height and vertical velocity from IMU + barometer (paper 003) on DDS.
//   in:  imu (ImuSample with pressure)     out: altitude (AltitudeEstimate), diagnostics
//   params: filter_file (YAML of AltitudeParams), method (overrides the file: pi_cf_zupt, cf_zupt,
//           pi_cf, two_step_kf), relative_to_start (report heights above the start: the mean
//           barometric height over the first second; nothing is published during that second;
//           default false: heights above the reference pressure level),
//           node keys (NodeParams)
#include "poise/altitude/altitude_filter.h"
#include "poise/dds/convert.h"
#include "poise/nodes/imu_estimator_node.h"
#include "poise/nodes/register.h"

#include <poise/msg/estimates.h>

#include <optional>

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

/// The message of an estimate; heights relative to `zero_m` (0: above the reference level).
msg::AltitudeEstimate to_altitude_msg(const AltitudeEstimate& e, const AltitudeParams& p, double zero_m,
                                      const ImuSample& sample, const std::string& sensor_id) {
  msg::AltitudeEstimate out;
  out.header(dds::make_header(sample.stamp_ns, sample.seq, "world"));
  out.sensor_id(sensor_id);
  out.filter_id("altitude");
  out.method(to_string(p.method));
  out.height_m(e.height_m - zero_m);
  out.vertical_velocity_mps(e.vertical_velocity_mps);
  out.vertical_accel_mps2(e.vertical_accel_mps2);
  out.stationary(e.stationary);
  out.baro_valid(e.baro_fresh);
  out.baro_height_m(e.baro_height_m - zero_m);
  out.reference_pressure_pa(p.reference_pressure_pa);
  return out;
}

class AltitudeStep : public EstimatorStep {
 public:
  explicit AltitudeStep(const runtime::ComponentSpec& spec)
      : EstimatorStep(spec.name, "altitude"),
        relative_(runtime::param<bool>(spec, "relative_to_start", false)),
        filter_(load_params(spec)) {}

  [[nodiscard]] unsigned kinds() const override { return kAltitudeOut; }
  bool step(const ImuSample& sample) override { return filter_.update(sample); }
  bool estimate(const ImuSample& sample, StepOutputs& out) override {
    const AltitudeEstimate& e = filter_.estimate();
    if (!e.valid) {
      return false;
    }
    const std::optional<double> zero = relative_ ? start_zero_.add(e) : std::optional<double>(0.0);
    if (!zero) {
      return false;  // relative_to_start: the zero is still being averaged
    }
    out.altitude(to_altitude_msg(e, filter_.params(), *zero, sample, sensor_id()));
    return true;
  }
  void diagnostics(DiagnosticsReport& diag) const override {
    diag.sources = filter_.sources();
    diag.counters = filter_.rejects().to_map();  // per reason of the shared check
    diag.counters["state_resets"] = filter_.state_resets();
  }

 private:
  bool relative_;
  AltitudeFilter filter_;
  StartZero start_zero_;
};

}  // namespace

std::unique_ptr<EstimatorStep> make_altitude_step(const runtime::ComponentSpec& spec) {
  return std::make_unique<AltitudeStep>(spec);
}

void register_altitude_node(runtime::ComponentRegistry& registry) {
  registry.add(estimator_component(
      "altitude", "Height and vertical velocity from IMU + barometer (PI complementary filter + ZUPT)",
      &make_altitude_step));
}

}  // namespace poise::nodes
