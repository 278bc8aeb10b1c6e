// Component `gauss_newton`: the Gauss-Newton orientation baseline on DDS.
//   in:  imu            out: attitude/gauss_newton, diagnostics
//   params: filter_file (YAML of GaussNewtonParams), node keys (NodeParams), north (estimator_step.h north_keys())
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/nodes/imu_estimator_node.h"
#include "poise/nodes/register.h"

#include <poise/msg/estimates.h>

namespace poise::nodes {
namespace {

GaussNewtonParams load_params(const runtime::ComponentSpec& spec, const NorthReference& north) {
  std::vector<std::string> known = NodeParams::keys();
  known.insert(known.end(), north_keys().begin(), north_keys().end());
  known.emplace_back("filter_file");
  runtime::check_known_params(spec, known);
  const auto file = runtime::param<std::string>(spec, "filter_file", "");
  try {
    GaussNewtonParams p = file.empty() ? GaussNewtonParams{} : load_gauss_newton_params(file);
    double unused_magnitude_ut = 0.0;  // the baseline has no magnitude reference
    seed_field_reference(north, unused_magnitude_ut, p.dip_deg);
    return p;
  } catch (const std::exception& e) {
    throw runtime::ConfigError(spec.origin + ": " + e.what());
  }
}

class GaussNewtonStep : public AttitudeStep {
 public:
  explicit GaussNewtonStep(const runtime::ComponentSpec& spec)
      : AttitudeStep(spec.name, "gauss_newton", north_reference(spec)), gn_(load_params(spec, north())) {}

  bool step(const ImuSample& sample) override { return gn_.update(sample); }
  bool attitude(AttitudeReport& report) const override {
    if (!gn_.initialized()) {
      return false;
    }
    report.q_world_body = gn_.result().q_world_body;
    report.covariance = gn_.attitude_covariance();
    const SourceReports sources = gn_.sources();  // both fused for every estimate it gives
    report.sources_fused = sources_fused_bits(sources);
    report.mag_trusted = source_fused(sources, Source::kMag);
    report.heading_status = gn_.heading_status();
    return true;
  }
  void diagnostics(DiagnosticsReport& diag) const override {
    diag.sources = gn_.sources();
    diag.counters = gn_.rejections().to_map();
    diag.counters["state_resets"] = gn_.state_resets();
    diag.metrics = {{"iterations", static_cast<double>(gn_.result().iterations), ""},
                    {"residual", gn_.result().residual, ""}};
  }

 private:
  GaussNewton gn_;
};

}  // namespace

std::unique_ptr<EstimatorStep> make_gauss_newton_step(const runtime::ComponentSpec& spec) {
  return std::make_unique<GaussNewtonStep>(spec);
}

void register_gauss_newton_node(runtime::ComponentRegistry& registry) {
  registry.add(estimator_component(
      "gauss_newton", "Gauss-Newton orientation from accelerometer + magnetometer (baseline)",
      &make_gauss_newton_step));
}

}  // namespace poise::nodes
