// Component `selective_ekf`: the selective EKF (paper 002) on DDS.
//   in:  imu (ImuSample), vision_pose (VisionPose: pose_world_camera at its capture time)
//   out: attitude/selective_ekf (AttitudeEstimate), pose/selective_ekf (PoseEstimate), diagnostics
//   params: filter_file (YAML of SelectiveEkfParams), q_body_camera [w,x,y,z] and
//           p_body_camera_m [x,y,z] (camera-to-IMU extrinsic; override the file), imu_delay_s
//           (the IMU's group delay, s; overrides the file; without it here or in the file, the
//           delay the IMU's driver publishes on `imu_info`: poise/nodes/imu_delay.h; one that
//           arrives after the first sample restarts the EKF with it), vision_time_offset_s,
//           vision_time_offset_sigma_s (the camera-IMU time offset's prior and its sigma, s; sigma
//           > 0 estimates it online) and predict_horizon_s (override the file; see below),
//           gyro_noise_density_rps_per_sqrt_hz, accel_noise_density_mps2_per_sqrt_hz,
//           gyro_bias_walk_rps_per_sqrt_s (figures of the sensor, for the published covariance
//           only; override the file; a simulated IMU's host says its own), node
//           keys (NodeParams), north
//           (declination_deg | location + date: estimator_step.h north_keys(); vision poses are
//           then taken as true ENU and turned into the filter's magnetic ENU)
// predict_horizon_s > 0 (issue 36, an AR renderer's display time): attitude/<name> and
// pose/<name> carry the pose predicted to the IMU sample's stamp + the horizon (SelectiveEkf::
// predict), stamped with that instant, covariance grown over the horizon; 0 (default) = the pose
// at the sample's stamp. Diagnostics: the time offset in use, its sigma and convergence (metrics
// vision_time_offset, vision_time_offset_sigma, vision_time_offset_converged) and the pairs'
// decisions (counters time_offset_<decision>).
// The EKF applies its own camera-to-body extrinsic to the camera pose (the message's body pose is
// not used), so the extrinsic is configured in one place for the filter.
#include "poise/dds/convert.h"
#include "poise/nodes/imu_estimator_node.h"
#include "poise/nodes/register.h"
#include "poise/selective_ekf/selective_ekf.h"

#include <poise/msg/estimates.h>
#include <poise/msg/vision.h>

#include <cmath>
#include <cstdint>
#include <string>

namespace poise::nodes {
namespace {

SelectiveEkfParams load_params(const runtime::ComponentSpec& spec, const NorthReference& north) {
  std::vector<std::string> known = NodeParams::keys();
  known.insert(known.end(), north_keys().begin(), north_keys().end());
  known.insert(known.end(), {"filter_file", "q_body_camera", "p_body_camera_m", "imu_delay_s", "vision_time_offset_s",
                             "vision_time_offset_sigma_s", "predict_horizon_s", "gyro_noise_density_rps_per_sqrt_hz",
                             "accel_noise_density_mps2_per_sqrt_hz", "gyro_bias_walk_rps_per_sqrt_s"});
  runtime::check_known_params(spec, known);
  SelectiveEkfParams p;
  const auto file = runtime::param<std::string>(spec, "filter_file", "");
  try {
    if (!file.empty()) {
      p = load_selective_ekf_params(file);
    }
    const auto q = runtime::param<std::vector<double>>(spec, "q_body_camera", {});
    if (!q.empty()) {
      if (q.size() != 4) {
        throw runtime::ConfigError("q_body_camera must be [w, x, y, z]");
      }
      p.q_body_camera = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized();
    }
    const auto t = runtime::param<std::vector<double>>(spec, "p_body_camera_m", {});
    if (!t.empty()) {
      if (t.size() != 3) {
        throw runtime::ConfigError("p_body_camera_m must be [x, y, z]");
      }
      p.p_body_camera_m = Eigen::Vector3d(t[0], t[1], t[2]);
    }
    p.imu_delay_s = runtime::param<double>(spec, "imu_delay_s", p.imu_delay_s);
    p.vision_time_offset_s = runtime::param<double>(spec, "vision_time_offset_s", p.vision_time_offset_s);
    p.vision_time_offset_sigma_s =
        runtime::param<double>(spec, "vision_time_offset_sigma_s", p.vision_time_offset_sigma_s);
    p.predict_horizon_s = runtime::param<double>(spec, "predict_horizon_s", p.predict_horizon_s);
    // figures of the sensor, for the published covariance only (override the file)
    for (auto [key, value] : {std::pair{"gyro_noise_density_rps_per_sqrt_hz", &p.gyro_noise_density_rps_per_sqrt_hz},
                              std::pair{"accel_noise_density_mps2_per_sqrt_hz", &p.accel_noise_density_mps2_per_sqrt_hz},
                              std::pair{"gyro_bias_walk_rps_per_sqrt_s", &p.gyro_bias_walk_rps_per_sqrt_s}}) {
      *value = runtime::param<double>(spec, key, *value);
    }
    seed_field_reference(north, p.field_magnitude_ut, p.dip_deg);
    validate(p);
  } catch (const std::exception& e) {
    throw runtime::ConfigError(spec.origin + ": " + e.what());
  }
  return p;
}

/// The prediction horizon in ns (predict_horizon_s; 0 when the core has no sample yet).
int64_t selective_ekf_predict_ns(const SelectiveEkf& ekf) {
  return static_cast<int64_t>(std::llround(ekf.params().predict_horizon_s * 1e9));
}

class SelectiveEkfStep : public AttitudeStep {
 public:
  explicit SelectiveEkfStep(const runtime::ComponentSpec& spec)
      : AttitudeStep(spec.name, "selective_ekf", north_reference(spec)),
        ekf_(load_params(spec, north())),
        delay_(ekf_.params().imu_delay_s,
               imu_delay_configured(spec, runtime::param<std::string>(spec, "filter_file", ""), "selective_ekf")) {}

  bool published_imu_delay(double delay_s, const std::string& what) override {
    if (!delay_.offer(delay_s, what)) {
      return false;
    }
    if (ekf_.initialized()) {
      ekf_.reset();  // the state's time is the IMU stamp minus the delay: restart on the new one
    }
    ekf_.set_imu_delay_s(delay_s);
    return true;
  }
  [[nodiscard]] const ImuDelayChoice* imu_delay() const override { return &delay_; }

  [[nodiscard]] unsigned kinds() const override { return kAttitudeOut | kPoseOut; }
  [[nodiscard]] bool uses_vision() const override { return true; }
  void vision(const msg::VisionPose& m) override {
    // a tag map on true north (declination set) -> the filter's magnetic ENU
    ekf_.update_vision(to_vision_pose(north().to_magnetic(dds::camera_pose_from_msg(m))));
  }

  bool step(const ImuSample& sample) override { return ekf_.update_imu(sample); }
  bool attitude(AttitudeReport& report) const override {
    if (!ekf_.initialized()) {
      return false;
    }
    const MagStatus& mag = ekf_.mag_status();
    const PredictedAttitude predicted = ekf_.predict_horizon();  // horizon 0: the output itself
    report.q_world_body = predicted.q_world_body;
    report.covariance = predicted.covariance;
    report.heading_status = ekf_.heading_status();
    const SourceReports sources = selective_ekf_sources(ekf_);
    report.sources_fused = sources_fused_bits(sources);
    // its selective test (eqs. 8-10), not the bit: the heading row is fused inflated while untrusted
    report.mag_trusted = source_fused(sources, Source::kMag);
    report.mag_disturbance_angle_rad = std::abs(mag.disturbance_angle_deg - mag.reference_angle_deg) * kRadPerDeg;
    report.gyro_bias_rps = ekf_.state().b_rps;
    return true;
  }
  bool estimate(const ImuSample& sample_in, StepOutputs& out) override {
    ImuSample sample = sample_in;  // stamped with the instant the (predicted) pose is for
    sample.stamp_ns += selective_ekf_predict_ns(ekf_);
    if (!AttitudeStep::estimate(sample, out)) {
      return false;
    }
    const double horizon_s = static_cast<double>(sample.stamp_ns - sample_in.stamp_ns) * 1e-9;
    const AttitudeReport& report = last_report();
    msg::PoseEstimate pose;
    pose.header(dds::make_header(sample.stamp_ns, sample.seq, report.frame_id));
    pose.sensor_id(sensor_id());
    pose.filter_id(component());
    pose.position_m(dds::to_msg(north().to_true(Eigen::Vector3d(ekf_.position_m() + ekf_.state().v_mps * horizon_s))));
    pose.velocity_mps(dds::to_msg(north().to_true(ekf_.state().v_mps)));
    pose.q_world_body(dds::to_msg(report.q_world_body));
    Eigen::Matrix<double, 9, 9> cov = pose_covariance_world(ekf_);
    if (horizon_s > 0.0) {  // the attitude block grown over the horizon (magnetic ENU as the core's)
      cov.bottomRightCorner<3, 3>() += ekf_.predict_horizon().covariance - attitude_covariance_world(ekf_);
    }
    dds::to_array(north().rotate_covariance<9>(cov, false), pose.covariance());
    pose.sources_fused(report.sources_fused);
    out.pose(pose);
    return true;
  }
  void diagnostics(DiagnosticsReport& diag) const override {
    const MagStatus& mag = ekf_.mag_status();
    diag.sources = selective_ekf_sources(ekf_);
    diag.counters = ekf_.imu_rejections().to_map();
    const VisionCounters& vc = ekf_.vision_counters();
    diag.counters["vision_received"] = vc.received;
    diag.counters["vision_applied"] = vc.applied;
    diag.counters["vision_out_of_order"] = vc.out_of_order;
    diag.counters["rejected_vision_too_old"] = vc.too_old;
    diag.counters["rejected_vision_bad_input"] = vc.bad_input;
    diag.counters["mag_untrusted_samples"] = mag.untrusted_samples;
    diag.counters["state_resets"] = ekf_.state_resets();
    diag.metrics = {{"disturbance_angle", mag.disturbance_angle_deg * kRadPerDeg, "rad"},
                    {"reference_angle", mag.reference_angle_deg * kRadPerDeg, "rad"},
                    {"quat_error", mag.quat_error_deg * kRadPerDeg, "rad"}};
    const VisionTimeOffsetStatus& to = ekf_.vision_time_offset();
    if (to.estimating) {
      diag.metrics.push_back({"vision_time_offset", to.offset_s, "s"});
      diag.metrics.push_back({"vision_time_offset_sigma", to.sigma_s, "s"});
      diag.metrics.push_back({"vision_time_offset_converged", to.converged ? 1.0 : 0.0, ""});
      for (size_t d = 1; d < static_cast<size_t>(TimeOffsetDecision::kCount); ++d) {
        diag.counters[std::string("time_offset_") + to_string(static_cast<TimeOffsetDecision>(d))] = to.by_decision[d];
      }
    }
  }

 private:
  SelectiveEkf ekf_;
  ImuDelayChoice delay_;
};

}  // namespace

std::unique_ptr<EstimatorStep> make_selective_ekf_step(const runtime::ComponentSpec& spec) {
  return std::make_unique<SelectiveEkfStep>(spec);
}

void register_selective_ekf_node(runtime::ComponentRegistry& registry) {
  registry.add(estimator_component(
      "selective_ekf", "Selective EKF: gyro + Gauss-Newton IMU quaternion + AprilTag vision, magnetometer gated",
      &make_selective_ekf_step));
}

}  // namespace poise::nodes
