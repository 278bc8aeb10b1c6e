// Component `vehicle`: vehicle attitude (paper 001: TRIAD when static, EKF with the roll/pitch
// model when driving) on DDS.
//   in:  imu (longitudinal/lateral specific force = body x/y, yaw rate = body z, magnetometer),
//        vehicle_input (speed; the latest valid one is used with each IMU sample)
//   out: attitude/vehicle (AttitudeEstimate), diagnostics
//   params: filter_file (YAML of VehicleParams), node keys (NodeParams), north (imu_node.h north_keys())
// Body frame: x forward, y left, z up (the vehicle's axes; remap the IMU in the driver's YAML).
#include "poise/nodes/imu_estimator_node.h"
#include "poise/nodes/register.h"
#include "poise/vehicle/vehicle_estimator.h"

#include <poise/msg/estimates.h>
#include <poise/msg/imu.h>

namespace poise::nodes {
namespace {

VehicleParams load_params(const runtime::ComponentSpec& spec) {
  std::vector<std::string> known = NodeParams::keys();
  known.insert(known.end(), north_keys().begin(), north_keys().end());  // read by AttitudeStep
  known.emplace_back("filter_file");
  runtime::check_known_params(spec, known);
  const auto file = runtime::param<std::string>(spec, "filter_file", "");
  try {
    return file.empty() ? VehicleParams{} : load_vehicle_params(file);
  } catch (const std::exception& e) {
    throw runtime::ConfigError(spec.origin + ": " + e.what());
  }
}

class VehicleStep : public AttitudeStep {
 public:
  explicit VehicleStep(const runtime::ComponentSpec& spec)
      : AttitudeStep(spec.name, "vehicle", north_reference(spec)), estimator_(load_params(spec)) {}

  [[nodiscard]] bool uses_vehicle_input() const override { return true; }
  /// The latest VehicleInput (speed and its validity) goes with each following IMU sample.
  void vehicle_input(const msg::VehicleInput& m) override {
    has_speed_ = m.speed_valid();
    speed_mps_ = m.speed_mps();
  }
  bool step(const ImuSample& s) override {
    return estimator_.update(vehicle_sample_from_imu(s, has_speed_, speed_mps_));
  }
  bool attitude(AttitudeReport& report) const override {
    const VehicleEstimate& e = estimator_.estimate();
    if (!e.valid) {
      return false;
    }
    const SourceReports sources = estimator_.sources();
    report.q_world_body = e.q_world_body;
    report.sources_fused = sources_fused_bits(sources);
    report.mag_trusted = source_fused(sources, Source::kMag);
    report.heading_status = heading_status_from_mag(sources);
    return true;
  }
  void diagnostics(DiagnosticsReport& diag) const override {
    const VehicleEstimate& e = estimator_.estimate();
    const VehicleRejects& r = estimator_.rejects();
    diag.sources = estimator_.sources();
    diag.counters = r.samples.to_map();  // per reason of the shared check
    diag.counters["rejected_bad_speed"] = r.bad_speed;
    diag.counters["missing_mag"] = r.missing_mag;
    diag.counters["rejected_disturbed_mag"] = r.disturbed_mag;
    diag.counters["state_resets"] = estimator_.state_resets();
    diag.metrics = {{"static", e.is_static ? 1.0 : 0.0, ""}, {"from_triad", e.from_triad ? 1.0 : 0.0, ""}};
  }

 private:
  VehicleEstimator estimator_;
  bool has_speed_ = false;
  double speed_mps_ = 0.0;
};

}  // namespace

std::unique_ptr<EstimatorStep> make_vehicle_step(const runtime::ComponentSpec& spec) {
  return std::make_unique<VehicleStep>(spec);
}

void register_vehicle_node(runtime::ComponentRegistry& registry) {
  registry.add(estimator_component(
      "vehicle", "Vehicle attitude: TRIAD when static, roll/pitch-model EKF when driving",
      &make_vehicle_step));
}

}  // namespace poise::nodes
