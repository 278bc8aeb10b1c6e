// Component `selective_ekf`: the selective EKF (paper 002) on DDS.
//   in:  imu (ImuSample), vision_pose (VisionPose: pose_world_camera at its capture time)
//   out: attitude/selective_ekf (AttitudeEstimate), pose/selective_ekf (PoseEstimate), diagnostics
//   params: filter_file (YAML of SelectiveEkfParams), q_body_camera [w,x,y,z] and
//           p_body_camera_m [x,y,z] (camera-to-IMU extrinsic; override the file), imu_delay_s
//           (the IMU's group delay, s; overrides the file), diagnostics_every
// The EKF applies its own camera-to-body extrinsic to the camera pose (the message's body pose is
// not used), so the extrinsic is configured in one place for the filter.
#include "poise/dds/convert.h"
#include "poise/nodes/imu_node.h"
#include "poise/nodes/register.h"
#include "poise/selective_ekf/selective_ekf.h"

#include <poise/msg/estimates.h>
#include <poise/msg/visionPubSubTypes.h>

#include <cmath>

namespace poise::nodes {
namespace {

SelectiveEkfParams load_params(const runtime::ComponentSpec& spec) {
  std::vector<std::string> known = NodeParams::keys();
  known.insert(known.end(), {"filter_file", "q_body_camera", "p_body_camera_m", "imu_delay_s"});
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
    validate(p);
  } catch (const std::exception& e) {
    throw runtime::ConfigError(spec.origin + ": " + e.what());
  }
  return p;
}

/// The filter's vision input from a message: camera pose at capture time, per-axis std from the
/// covariance diagonal (NaN when the covariance is not usable: the filter's defaults apply).
VisionPose vision_input(const msg::VisionPose& m) {
  VisionPose v;
  v.capture_stamp_ns = m.capture_stamp_ns();
  v.q_world_camera = dds::from_msg(m.pose_world_camera().orientation());
  v.p_world_camera_m = dds::from_msg(m.pose_world_camera().position_m());
  const Eigen::Matrix<double, 6, 6> cov = dds::from_array<6, 6>(m.covariance());
  const double var_p = cov.diagonal().head<3>().mean();
  const double var_r = cov.diagonal().tail<3>().mean();
  v.sigma_m = var_p > 0.0 && std::isfinite(var_p) ? std::sqrt(var_p) : std::nan("");
  v.sigma_rad = var_r > 0.0 && std::isfinite(var_r) ? std::sqrt(var_r) : std::nan("");
  return v;
}

SourceReport source_report(const char* name, const SourceStatus& s) {
  SourceReport r;
  r.source = name;
  r.fresh = s.last != Decision::kNone;
  r.fused = s.last == Decision::kFused || s.last == Decision::kFusedInflated || s.last == Decision::kReset;
  r.reason = r.fused ? "" : to_string(s.last);
  r.innovation = {s.innovation.x(), s.innovation.y(), s.innovation.z()};
  r.innovation_variance = {s.innovation_variance.x(), s.innovation_variance.y(), s.innovation_variance.z()};
  r.test_ratio = s.test_ratio;
  r.last_fused_stamp_ns = std::max<int64_t>(0, s.last_fused_stamp_ns);
  r.fused_count = s.fused;
  r.rejected_count = s.rejected;
  return r;
}

class SelectiveEkfNode : public ImuAttitudeNode {
 public:
  SelectiveEkfNode(const runtime::ComponentSpec& spec, runtime::HostContext& host)
      : ImuAttitudeNode(spec, host, "selective_ekf"),
        ekf_(load_params(spec)),
        pose_writer_(host.participant, host.topics.pose("selective_ekf"), dds::QosKind::kEstimate) {}

  void start() override {
    ImuAttitudeNode::start();
    if (!vision_reader_) {
      vision_reader_ = std::make_unique<dds::Reader<msg::VisionPosePubSubType>>(
          host().participant, host().topics.vision_pose, dds::QosKind::kEstimate,
          [this](const msg::VisionPose& m, const auto&) {
            std::lock_guard<std::mutex> lock(mutex());
            ekf_.update_vision(vision_input(m));
          });
    }
  }
  void stop() override {
    vision_reader_.reset();
    ImuAttitudeNode::stop();
  }

 protected:
  bool step(const ImuSample& sample, AttitudeReport& report, DiagnosticsReport& diag) override {
    if (!ekf_.update_imu(sample) || !ekf_.initialized()) {
      return false;
    }
    const auto& x = ekf_.state();
    const MagStatus& mag = ekf_.mag_status();
    report.stamp_ns = sample.stamp_ns;
    report.seq = sample.seq;
    report.q_world_body = ekf_.q_world_body();
    const Eigen::Vector3d sigma_rad = ekf_.attitude_sigma_deg() * M_PI / 180.0;
    report.covariance = sigma_rad.cwiseAbs2().asDiagonal();
    report.mag_trusted = mag.trusted;
    report.mag_disturbance_angle_rad = mag.disturbance_angle_deg * M_PI / 180.0;
    const auto& vision = ekf_.status(Source::kVisionAttitude);
    const bool vision_recent = vision.last_fused_stamp_ns >= 0 &&
                               sample.stamp_ns - vision.last_fused_stamp_ns < 1'000'000'000;
    report.sources_fused = msg::SOURCE_GYRO | (mag.trusted ? msg::SOURCE_IMU_QUAT : 0U) |
                           (vision_recent ? msg::SOURCE_VISION : 0U);

    msg::PoseEstimate pose;
    pose.header(dds::make_header(sample.stamp_ns, sample.seq, "world"));
    pose.sensor_id(sensor_id());
    pose.filter_id("selective_ekf");
    pose.position_m(dds::to_msg(ekf_.position_m()));
    pose.velocity_mps(dds::to_msg(x.v_mps));
    pose.q_world_body(dds::to_msg(report.q_world_body));
    // 9x9 [p v theta] from the filter's 12x12 [w theta t v].
    const int blocks[3] = {SelectiveEkf::kT, SelectiveEkf::kV, SelectiveEkf::kTh};
    Eigen::Matrix<double, 9, 9> cov;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        cov.block<3, 3>(3 * i, 3 * j) = x.P.block<3, 3>(blocks[i], blocks[j]);
      }
    }
    dds::to_array(cov, pose.covariance());
    pose.sources_fused(report.sources_fused);
    pose_writer_.write(pose);

    diag.sources = {source_report("gyro", ekf_.status(Source::kGyro)),
                    source_report("imu_quat", ekf_.status(Source::kImuQuat)),
                    source_report("vision_attitude", ekf_.status(Source::kVisionAttitude)),
                    source_report("vision_position", ekf_.status(Source::kVisionPosition))};
    diag.counters = ekf_.imu_rejections().to_map();
    const VisionCounters& vc = ekf_.vision_counters();
    diag.counters["vision_received"] = vc.received;
    diag.counters["vision_applied"] = vc.applied;
    diag.counters["vision_out_of_order"] = vc.out_of_order;
    diag.counters["rejected_vision_too_old"] = vc.too_old;
    diag.counters["rejected_vision_bad_input"] = vc.bad_input;
    diag.counters["mag_untrusted_samples"] = mag.untrusted_samples;
    diag.metrics = {{"disturbance_angle", mag.disturbance_angle_deg, "deg"},
                    {"reference_angle", mag.reference_angle_deg, "deg"},
                    {"quat_error", mag.quat_error_deg, "deg"}};
    return true;
  }

 private:
  SelectiveEkf ekf_;
  dds::Writer<msg::PoseEstimatePubSubType> pose_writer_;
  std::unique_ptr<dds::Reader<msg::VisionPosePubSubType>> vision_reader_;
};

}  // namespace

void register_selective_ekf_node(runtime::ComponentRegistry& registry) {
  registry.add({"selective_ekf",
                "Selective EKF: gyro + Gauss-Newton IMU quaternion + AprilTag vision, magnetometer gated",
                [](const runtime::ComponentSpec& spec, runtime::HostContext& host) {
                  return std::make_unique<SelectiveEkfNode>(spec, host);
                }});
}

}  // namespace poise::nodes
