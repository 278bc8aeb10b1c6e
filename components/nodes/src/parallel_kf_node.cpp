// Component `parallel_kf`: the parallel Kalman filter (paper 000) on DDS.
//   in:  imu (ImuSample)      out: attitude/parallel_kf (AttitudeEstimate), diagnostics
//   params: preset (default | paper), filter_file (YAML of ParallelKfParams), node keys (NodeParams),
//           north (declination_deg | location + date: estimator_step.h north_keys())
#include "poise/nodes/imu_estimator_node.h"
#include "poise/nodes/register.h"
#include "poise/parallel_kf/parallel_kf.h"

#include <poise/msg/estimates.h>


namespace poise::nodes {
namespace {

ParallelKfParams load_params(const runtime::ComponentSpec& spec, const NorthReference& north) {
  std::vector<std::string> known = NodeParams::keys();
  known.insert(known.end(), north_keys().begin(), north_keys().end());
  known.insert(known.end(), {"preset", "filter_file"});
  runtime::check_known_params(spec, known);
  const auto file = runtime::param<std::string>(spec, "filter_file", "");
  try {
    ParallelKfParams p = file.empty() ? ParallelKfParams::named(runtime::param<std::string>(spec, "preset", "default"))
                                      : load_parallel_kf_params(file);
    seed_field_reference(north, p.field_magnitude_ut, p.dip_deg);
    p.validate();
    return p;
  } catch (const std::exception& e) {
    throw runtime::ConfigError(spec.origin + ": " + e.what());
  }
}

class ParallelKfStep : public AttitudeStep {
 public:
  explicit ParallelKfStep(const runtime::ComponentSpec& spec)
      : AttitudeStep(spec.name, "parallel_kf", north_reference(spec)), kf_(load_params(spec, north())) {}

  bool step(const ImuSample& sample) override { return kf_.update(sample); }
  bool attitude(AttitudeReport& report) const override {
    if (!kf_.initialized()) {
      return false;
    }
    const ParallelKfOutput out = kf_.output();
    report.q_world_body = out.q_world_body;
    report.covariance = kf_.attitude_covariance(out);
    report.ext_accel_body_mps2 = out.ext_accel_body_mps2;
    report.ext_accel_world_mps2 = out.ext_accel_world_mps2;
    report.mag_disturbance_body_ut = out.mag_dist_body_ut;
    report.mag_disturbance_world_ut = out.mag_dist_world_ut;
    report.gyro_bias_rps = out.gyro_bias_rps;
    const SourceReports sources = kf_.sources();
    report.sources_fused = sources_fused_bits(sources);
    report.mag_trusted = source_fused(sources, Source::kMag);
    return true;
  }
  void diagnostics(DiagnosticsReport& diag) const override {
    const ParallelKfOutput out = kf_.output();
    diag.sources = kf_.sources();
    diag.counters = kf_.rejections().to_map();
    diag.counters["mag_gated_disturbed"] = kf_.mag_gated_count();
    diag.counters["mag_forced"] = kf_.mag_forced_count();
    diag.counters["field_reacquired"] = kf_.field_reacquired_count();
    diag.counters["state_resets"] = kf_.state_resets();
    diag.metrics = {{"field_magnitude", out.field_magnitude_ut, "uT"},
                    {"dip", out.dip_rad, "rad"},
                    {"disturbance_norm", out.mag_dist_norm_ut, "uT"},
                    {"rest", out.rest ? 1.0 : 0.0, ""}};
  }

 private:
  ParallelKf kf_;
};

}  // namespace

std::unique_ptr<EstimatorStep> make_parallel_kf_step(const runtime::ComponentSpec& spec) {
  return std::make_unique<ParallelKfStep>(spec);
}

void register_parallel_kf_node(runtime::ComponentRegistry& registry) {
  registry.add(estimator_component(
      "parallel_kf", "Parallel Kalman filter (tilt + external acceleration | heading + magnetic disturbance)",
      &make_parallel_kf_step));
}

}  // namespace poise::nodes
