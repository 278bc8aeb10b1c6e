// Component `parallel_kf`: the parallel Kalman filter (paper 000) on DDS.
//   in:  imu (ImuSample)      out: attitude/parallel_kf (AttitudeEstimate), diagnostics
//   params: preset (default | paper), filter_file (YAML of ParallelKfParams), diagnostics_every
#include "poise/nodes/imu_node.h"
#include "poise/nodes/register.h"
#include "poise/parallel_kf/parallel_kf.h"

#include <poise/msg/estimates.h>

#include <cmath>

namespace poise::nodes {
namespace {

ParallelKfParams load_params(const runtime::ComponentSpec& spec) {
  std::vector<std::string> known = NodeParams::keys();
  known.insert(known.end(), {"preset", "filter_file"});
  runtime::check_known_params(spec, known);
  const auto file = runtime::param<std::string>(spec, "filter_file", "");
  try {
    if (!file.empty()) {
      return load_parallel_kf_params(file);
    }
    return ParallelKfParams::named(runtime::param<std::string>(spec, "preset", "default"));
  } catch (const std::exception& e) {
    throw runtime::ConfigError(spec.origin + ": " + e.what());
  }
}

class ParallelKfNode : public ImuAttitudeNode {
 public:
  ParallelKfNode(const runtime::ComponentSpec& spec, runtime::HostContext& host)
      : ImuAttitudeNode(spec, host, "parallel_kf"), kf_(load_params(spec)) {}

 protected:
  bool step(const ImuSample& sample, AttitudeReport& report, DiagnosticsReport& diag) override {
    const uint64_t gated_before = kf_.mag_gated_count();
    if (!kf_.update(sample) || !kf_.initialized()) {
      return false;
    }
    const ParallelKfOutput out = kf_.output();
    report.stamp_ns = sample.stamp_ns;
    report.seq = sample.seq;
    report.q_world_body = out.q_world_body;
    report.covariance = kf_.attitude_covariance(out);
    report.ext_accel_body_mps2 = out.ext_accel_body_mps2;
    report.ext_accel_world_mps2 = out.ext_accel_world_mps2;
    report.mag_disturbance_body_ut = out.mag_dist_body_ut;
    report.mag_disturbance_world_ut = out.mag_dist_world_ut;
    report.mag_trusted = out.mag_used;
    report.gyro_bias_rps = out.gyro_bias_rps;
    report.sources_fused = msg::SOURCE_GYRO | msg::SOURCE_ACCEL | (out.mag_used ? msg::SOURCE_MAG : 0U);

    SourceReport accel;
    accel.source = "accel";
    accel.fresh = true;
    accel.fused = true;
    SourceReport mag;
    mag.source = "mag";
    mag.fresh = sample.has_mag;
    mag.fused = out.mag_used;
    if (!out.mag_used) {
      mag.reason = !sample.has_mag ? "no_sample"
                   : kf_.mag_gated_count() != gated_before ? "disturbed"
                   : !out.field_learnt ? "learning_field"
                                        : "not_used";
    }
    mag.rejected_count = kf_.mag_gated_count();
    diag.sources = {accel, mag};
    diag.counters = kf_.rejections().to_map();
    diag.counters["mag_gated_disturbed"] = kf_.mag_gated_count();
    diag.counters["field_reacquired"] = kf_.field_reacquired_count();
    diag.metrics = {{"field_magnitude", out.field_magnitude_ut, "uT"},
                    {"dip", out.dip_rad * 180.0 / M_PI, "deg"},
                    {"disturbance_norm", out.mag_dist_norm_ut, "uT"},
                    {"rest", out.rest ? 1.0 : 0.0, ""}};
    return true;
  }

 private:
  ParallelKf kf_;
};

}  // namespace

void register_parallel_kf_node(runtime::ComponentRegistry& registry) {
  registry.add({"parallel_kf",
                "Parallel Kalman filter (tilt + external acceleration | heading + magnetic disturbance)",
                [](const runtime::ComponentSpec& spec, runtime::HostContext& host) {
                  return std::make_unique<ParallelKfNode>(spec, host);
                }});
}

}  // namespace poise::nodes
