// Component `parallel_kf`: the parallel Kalman filter (paper 000) on DDS.
//   in:  imu (ImuSample)      out: attitude/parallel_kf (AttitudeEstimate), diagnostics
//   params: preset (default | paper), filter_file (YAML of ParallelKfParams), imu_delay_s (the
//           IMU's group delay, s; overrides the file), gyro_bias_walk_rps_per_sqrt_s (the gyro's
//           own bias walk, rad/s/sqrt(s), for the published covariance; overrides the file; a
//           simulated IMU's host says its figure), gyro_noise_density_rps_per_sqrt_hz (the gyro's
//           white noise density, rad/s/sqrt(Hz), for the published covariance; overrides the
//           file), gyro_initial_bias_sd_rps (the spread of the gyro's bias at start, rad/s, the
//           same way), gyro_scale_error (the gyro's own scale-factor error, relative, the same way),
//           node keys (NodeParams), north
//           (declination_deg | location + date: estimator_step.h north_keys())
//   Without imu_delay_s here or in the file, the delay the IMU's driver publishes on `imu_info`
//   is used (poise/nodes/imu_delay.h).
#include "poise/nodes/imu_estimator_node.h"
#include "poise/nodes/register.h"
#include "poise/parallel_kf/parallel_kf.h"

#include <poise/msg/estimates.h>


namespace poise::nodes {
namespace {

ParallelKfParams load_params(const runtime::ComponentSpec& spec, const NorthReference& north) {
  std::vector<std::string> known = NodeParams::keys();
  known.insert(known.end(), north_keys().begin(), north_keys().end());
  known.insert(known.end(), {"preset", "filter_file", "imu_delay_s", "gyro_bias_walk_rps_per_sqrt_s",
                              "gyro_noise_density_rps_per_sqrt_hz", "gyro_initial_bias_sd_rps", "gyro_scale_error"});
  runtime::check_known_params(spec, known);
  const auto file = runtime::param<std::string>(spec, "filter_file", "");
  try {
    ParallelKfParams p = file.empty() ? ParallelKfParams::named(runtime::param<std::string>(spec, "preset", "default"))
                                      : load_parallel_kf_params(file);
    p.imu_delay_s = runtime::param<double>(spec, "imu_delay_s", p.imu_delay_s);
    p.gyro_bias_walk_rps_per_sqrt_s =
        runtime::param<double>(spec, "gyro_bias_walk_rps_per_sqrt_s", p.gyro_bias_walk_rps_per_sqrt_s);
    p.gyro_noise_density_rps_per_sqrt_hz =
        runtime::param<double>(spec, "gyro_noise_density_rps_per_sqrt_hz", p.gyro_noise_density_rps_per_sqrt_hz);
    p.gyro_initial_bias_sd_rps = runtime::param<double>(spec, "gyro_initial_bias_sd_rps", p.gyro_initial_bias_sd_rps);
    p.gyro_scale_error = runtime::param<double>(spec, "gyro_scale_error", p.gyro_scale_error);
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
      : AttitudeStep(spec.name, "parallel_kf", north_reference(spec)),
        kf_(load_params(spec, north())),
        delay_(kf_.params().imu_delay_s,
               imu_delay_configured(spec, runtime::param<std::string>(spec, "filter_file", ""), "parallel_kf")) {}

  bool published_imu_delay(double delay_s, const std::string& what) override {
    if (!delay_.offer(delay_s, what)) {
      return false;
    }
    kf_.set_imu_delay_s(delay_s);  // the output's prediction only: any time
    return true;
  }
  [[nodiscard]] const ImuDelayChoice* imu_delay() const override { return &delay_; }

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
    report.heading_status = kf_.heading_status();
    return true;
  }
  void diagnostics(DiagnosticsReport& diag) const override {
    const ParallelKfOutput out = kf_.output();
    diag.sources = kf_.sources();
    diag.counters = kf_.rejections().to_map();
    diag.counters["mag_gated_disturbed"] = kf_.mag_gated_count();
    diag.counters["mag_forced"] = kf_.mag_forced_count();
    diag.counters["mag_hard_iron_corrected"] = kf_.mag_hard_iron_corrected_count();
    diag.counters["field_reacquired"] = kf_.field_reacquired_count();
    diag.counters["field_relearnt"] = kf_.field_relearnt_count();
    diag.counters["field_moved_by_offset"] = kf_.field_offset_moves_count();
    diag.counters["rest_turns_reverted"] = kf_.rest_turns_reverted_count();
    diag.counters["state_resets"] = kf_.state_resets();
    diag.metrics = {{"field_magnitude", out.field_magnitude_ut, "uT"},
                    {"dip", out.dip_rad, "rad"},
                    {"disturbance_norm", out.mag_dist_norm_ut, "uT"},
                    {"rest", out.rest ? 1.0 : 0.0, ""}};
  }

 private:
  ParallelKf kf_;
  ImuDelayChoice delay_;
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
