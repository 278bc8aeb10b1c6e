// GIVEN an estimator component's step (what its live node and `poise process` run) fed a scenario
// in which its core fuses known sources WHEN it writes its estimate THEN the estimate's
// sources_fused has the bits of exactly the sources the diagnostics of the same step say were
// fused (oracle: the hand-written name -> bit table of source_bits_oracle.h applied to the
// published SourceStatus list), and the bits the scenario implies are present, not only absent.
#include "node_harness.h"
#include "source_bits_oracle.h"

#include "poise/nodes/register.h"
#include "poise/nodes/reports.h"
#include "poise/vehicle/vehicle_estimator.h"

#include <gtest/gtest.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace poise::testing {
namespace {

constexpr uint32_t kSamples = 400;  // 4 s at 100 Hz: past every start-up phase (field 1 s, rest 1.5 s)
constexpr uint32_t kSettled = 300;  // from here on every scenario's sources are fused

/// The last message of each kind a step wrote.
struct Written : nodes::StepOutputs {
  std::optional<msg::AttitudeEstimate> attitude_msg;
  std::optional<msg::PoseEstimate> pose_msg;
  std::optional<msg::AltitudeEstimate> altitude_msg;
  void attitude(const msg::AttitudeEstimate& m) override { attitude_msg = m; }
  void pose(const msg::PoseEstimate& m) override { pose_msg = m; }
  void altitude(const msg::AltitudeEstimate& m) override { altitude_msg = m; }
  void diagnostics(const msg::FilterDiagnostics& /*m*/) override {}
};

/// One step's outputs and the diagnostics it would publish for the same sample.
struct StepResult {
  uint32_t seq = 0;
  Written out;
  msg::FilterDiagnostics diagnostics;
};

std::unique_ptr<nodes::EstimatorStep> make_step(const std::string& component_yaml) {
  runtime::ComponentSpec spec;
  const YAML::Node n = YAML::Load(component_yaml);
  spec.type = n["type"].as<std::string>();
  spec.name = spec.type;
  spec.params = n["params"] ? n["params"] : YAML::Node(YAML::NodeType::Map);
  spec.origin = "test";
  return nodes::make_estimator_step(spec);
}

/// Runs `kSamples` rest samples (body = ENU, clean field) through the step; `before` may change
/// a sample or feed a secondary input before the step sees it.
std::vector<StepResult> run(nodes::EstimatorStep& step,
                            const std::function<void(ImuSample&)>& before = [](ImuSample&) {}) {
  std::vector<StepResult> results;
  for (uint32_t seq = 0; seq < kSamples; ++seq) {
    ImuSample s = rest_sample(seq);
    before(s);
    StepResult r;
    r.seq = seq;
    if (!step.step(s)) {
      continue;
    }
    step.estimate(s, r.out);
    nodes::DiagnosticsReport report;
    step.diagnostics(report);
    r.diagnostics = nodes::to_diagnostics_msg(report, step.sensor_id());
    results.push_back(std::move(r));
  }
  return results;
}

/// The oracle: the bits of the sources the published diagnostics say were fused.
uint32_t bits_of_fused(const msg::FilterDiagnostics& d) {
  uint32_t bits = 0;
  for (const msg::SourceStatus& s : d.sources()) {
    const auto it = expected_source_bits().find(s.source().to_string());
    EXPECT_NE(it, expected_source_bits().end()) << "unknown source '" << s.source() << "'";
    if (s.fused() && it != expected_source_bits().end()) {
      bits |= it->second;
    }
  }
  return bits;
}

bool fused(const msg::FilterDiagnostics& d, const std::string& source) {
  return published_source(d, source).fused();
}

/// Every estimate's sources_fused equals the oracle of its step; returns how many were checked.
std::size_t expect_bits_match_diagnostics(const std::vector<StepResult>& results) {
  std::size_t checked = 0;
  for (const StepResult& r : results) {
    if (!r.out.attitude_msg) {
      continue;
    }
    EXPECT_EQ(r.out.attitude_msg->sources_fused(), bits_of_fused(r.diagnostics)) << "seq " << r.seq;
    if (r.out.pose_msg) {
      EXPECT_EQ(r.out.pose_msg->sources_fused(), r.out.attitude_msg->sources_fused()) << "seq " << r.seq;
    }
    ++checked;
  }
  return checked;
}

/// A selective EKF parameter file in the temporary directory, removed with the object.
class SelectiveEkfFile {
 public:
  explicit SelectiveEkfFile(const std::string& body)
      : path_(std::filesystem::temp_directory_path() /
              ("poise_sources_fused_" + std::to_string(::getpid()) + ".yaml")) {
    std::ofstream(path_) << "selective_ekf:\n" << body;
  }
  ~SelectiveEkfFile() { std::filesystem::remove(path_); }
  SelectiveEkfFile(const SelectiveEkfFile&) = delete;
  SelectiveEkfFile& operator=(const SelectiveEkfFile&) = delete;
  [[nodiscard]] std::string path() const { return path_.string(); }

 private:
  std::filesystem::path path_;
};

// The selective EKF in its default (split) mode fuses the low-passed accelerometer as tilt and
// the magnetometer as heading: SOURCE_ACCEL and SOURCE_MAG are set while it does (before the typed
// sources, accel_tilt and mag_heading carried no bit).
TEST(SourcesFused, GivenTheSelectiveEkfInSplitModeFusingTiltAndHeadingThenSourceAccelAndSourceMagAreSet) {
  const auto step = make_step("{type: selective_ekf}");
  const std::vector<StepResult> results = run(*step);
  EXPECT_GT(expect_bits_match_diagnostics(results), kSettled);
  bool heading_before_its_trust_test = false;
  for (const StepResult& r : results) {
    if (!r.out.attitude_msg) {
      continue;
    }
    const uint32_t bits = r.out.attitude_msg->sources_fused();
    if (fused(r.diagnostics, "accel_tilt")) {
      EXPECT_NE(bits & msg::SOURCE_ACCEL, 0U) << "seq " << r.seq << ": the tilt row was fused";
    }
    if (fused(r.diagnostics, "mag_heading")) {
      EXPECT_NE(bits & msg::SOURCE_MAG, 0U) << "seq " << r.seq << ": the heading row was fused";
      // while the field reference is learnt the mag (trust) report is not available, yet the
      // heading is fused: the bit comes from the heading row
      heading_before_its_trust_test = heading_before_its_trust_test || !fused(r.diagnostics, "mag");
    }
    if (r.seq >= kSettled) {
      EXPECT_TRUE(fused(r.diagnostics, "accel_tilt")) << "seq " << r.seq;
      EXPECT_TRUE(fused(r.diagnostics, "mag_heading")) << "seq " << r.seq;
      EXPECT_TRUE(fused(r.diagnostics, "zero_rate")) << "seq " << r.seq << ": at rest";
      EXPECT_EQ(bits, msg::SOURCE_GYRO | msg::SOURCE_ACCEL | msg::SOURCE_MAG) << "seq " << r.seq;
      EXPECT_TRUE(r.out.attitude_msg->mag_trusted()) << "seq " << r.seq;
    }
  }
  EXPECT_TRUE(heading_before_its_trust_test)
      << "the scenario should include heading fusions while the field reference is still learnt";
}

// Its other mode (the paper's): one Gauss-Newton quaternion from accelerometer and magnetometer.
TEST(SourcesFused, GivenTheSelectiveEkfInQuaternionModeThenSourceImuQuatAndSourceMagAreSet) {
  const SelectiveEkfFile file("  imu_measurement: quaternion\n");
  const auto step = make_step("{type: selective_ekf, params: {filter_file: '" + file.path() + "'}}");
  const std::vector<StepResult> results = run(*step);
  EXPECT_GT(expect_bits_match_diagnostics(results), kSettled);
  for (const StepResult& r : results) {
    if (r.seq < kSettled || !r.out.attitude_msg) {
      continue;
    }
    EXPECT_TRUE(fused(r.diagnostics, "imu_quat")) << "seq " << r.seq;
    EXPECT_FALSE(fused(r.diagnostics, "accel_tilt")) << "seq " << r.seq << ": no tilt row in this mode";
    EXPECT_EQ(r.out.attitude_msg->sources_fused(), msg::SOURCE_GYRO | msg::SOURCE_IMU_QUAT | msg::SOURCE_MAG)
        << "seq " << r.seq;
  }
}

// Tag poses at 33 Hz (the camera at the body, identity extrinsic): SOURCE_VISION set.
TEST(SourcesFused, GivenTheSelectiveEkfWithTagPosesThenSourceVisionIsSet) {
  const auto step = make_step("{type: selective_ekf}");
  const std::vector<StepResult> results = run(*step, [&step](ImuSample& s) {
    if (s.seq > 0 && s.seq % 3 == 0) {
      msg::VisionPose v;
      v.header(dds::make_header(s.stamp_ns, s.seq, "world"));
      v.capture_stamp_ns(s.stamp_ns);
      msg::Pose camera;
      camera.position_m(dds::to_msg(Eigen::Vector3d(0.0, 0.0, 1.0)));
      camera.orientation(dds::to_msg(Eigen::Quaterniond::Identity()));  // = the rest samples' body
      v.pose_world_camera(camera);
      Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Zero();
      cov.diagonal() << 1e-4, 1e-4, 1e-4, 3e-4, 3e-4, 3e-4;  // 1 cm, ~1 deg
      dds::to_array(cov, v.covariance());
      step->vision(v);
    }
  });
  EXPECT_GT(expect_bits_match_diagnostics(results), kSettled);
  for (const StepResult& r : results) {
    if (r.seq < kSettled || !r.out.attitude_msg) {
      continue;
    }
    EXPECT_TRUE(fused(r.diagnostics, "vision_attitude")) << "seq " << r.seq;
    EXPECT_TRUE(fused(r.diagnostics, "vision_position")) << "seq " << r.seq;
    EXPECT_NE(r.out.attitude_msg->sources_fused() & msg::SOURCE_VISION, 0U) << "seq " << r.seq;
    ASSERT_TRUE(r.out.pose_msg.has_value());
    EXPECT_NE(r.out.pose_msg->sources_fused() & msg::SOURCE_VISION, 0U) << "seq " << r.seq;
  }
}

TEST(SourcesFused, GivenTheParallelKfAtRestThenSourceGyroAccelAndMagAreSet) {
  const auto step = make_step("{type: parallel_kf}");
  const std::vector<StepResult> results = run(*step);
  EXPECT_GT(expect_bits_match_diagnostics(results), kSettled);
  for (const StepResult& r : results) {
    if (r.seq < kSettled || !r.out.attitude_msg) {
      continue;
    }
    EXPECT_TRUE(fused(r.diagnostics, "gyro") && fused(r.diagnostics, "accel") && fused(r.diagnostics, "mag"))
        << "seq " << r.seq;
    EXPECT_EQ(r.out.attitude_msg->sources_fused(), msg::SOURCE_GYRO | msg::SOURCE_ACCEL | msg::SOURCE_MAG)
        << "seq " << r.seq;
    EXPECT_TRUE(r.out.attitude_msg->mag_trusted()) << "seq " << r.seq;
  }
}

TEST(SourcesFused, GivenGaussNewtonThenSourceAccelAndMagAreSetForEveryEstimate) {
  const auto step = make_step("{type: gauss_newton}");
  const std::vector<StepResult> results = run(*step);
  EXPECT_EQ(expect_bits_match_diagnostics(results), kSamples) << "an estimate for every sample";
  for (const StepResult& r : results) {
    ASSERT_TRUE(r.out.attitude_msg.has_value());
    EXPECT_EQ(r.out.attitude_msg->sources_fused(), msg::SOURCE_ACCEL | msg::SOURCE_MAG) << "seq " << r.seq;
    EXPECT_TRUE(r.out.attitude_msg->mag_trusted()) << "seq " << r.seq;
  }
}

// Driving at 10 m/s (the EKF, not static TRIAD) in the configured field: the yaw rate, the
// accelerometer, the magnetometer and the speed are all used.
TEST(SourcesFused, GivenTheVehicleEstimatorDrivingThenSourceGyroAccelMagAndSpeedAreSet) {
  const auto step = make_step("{type: vehicle}");
  constexpr double kSpeedMps = 10.0;  // above static_speed_max_mps (0.5)
  const std::vector<StepResult> results = run(*step, [&step](ImuSample& s) {
    s.mag_ut = VehicleParams{}.mag_world_ut;  // level, facing east: the configured field
    msg::VehicleInput v;
    v.header(dds::make_header(s.stamp_ns, s.seq, "body"));
    v.speed_mps(kSpeedMps);
    v.speed_valid(true);
    step->vehicle_input(v);
  });
  EXPECT_GT(expect_bits_match_diagnostics(results), kSettled);
  for (const StepResult& r : results) {
    if (r.seq < kSettled || !r.out.attitude_msg) {
      continue;
    }
    EXPECT_TRUE(fused(r.diagnostics, "yaw_rate") && fused(r.diagnostics, "speed")) << "seq " << r.seq;
    EXPECT_EQ(r.out.attitude_msg->sources_fused(),
              msg::SOURCE_GYRO | msg::SOURCE_ACCEL | msg::SOURCE_MAG | msg::SOURCE_SPEED)
        << "seq " << r.seq;
    EXPECT_TRUE(r.out.attitude_msg->mag_trusted()) << "seq " << r.seq;
  }
}

// The altitude estimate has no sources_fused field: its diagnostics are where its fused sources
// appear (accelerometer, barometer and, at rest, the zero-velocity update).
TEST(SourcesFused, GivenTheAltitudeFilterWithABarometerThenItsDiagnosticsShowAccelBaroAndZuptFused) {
  const auto step = make_step("{type: altitude}");
  const std::vector<StepResult> results = run(*step, [](ImuSample& s) {
    s.has_pressure = true;
    s.pressure_pa = 100000.0;
  });
  std::size_t settled = 0;
  for (const StepResult& r : results) {
    if (r.seq < kSettled) {
      continue;
    }
    ASSERT_TRUE(r.out.altitude_msg.has_value()) << "seq " << r.seq;
    EXPECT_TRUE(fused(r.diagnostics, "accel")) << "seq " << r.seq;
    EXPECT_TRUE(fused(r.diagnostics, "baro")) << "seq " << r.seq;
    EXPECT_TRUE(fused(r.diagnostics, "zupt")) << "seq " << r.seq;
    ++settled;
  }
  EXPECT_EQ(settled, kSamples - kSettled);
}

}  // namespace
}  // namespace poise::testing

namespace poise::testing {
namespace {

constexpr double kTumbleRateHz = 100.0;  // sample rate, Hz
constexpr double kTumbleRestS = 2.0;     // at rest first (bias and field start-up), s
constexpr double kTumbleRunS = 30.0;     // whole run, s

// The parallel KF node's diagnostics count the magnetometer samples that had the hard-iron offset
// removed (counter mag_hard_iron_corrected, beside mag_gated_disturbed and mag_forced). Oracle:
// each step's published mag status. A step fused "hard_iron_corrected" adds exactly one; a step
// fused with no qualifier adds none; no step adds more than one. (A corrected reading the field
// gate then refuses says "disturbed", one that restarts the heading "heading_restarted": both
// still count, they were corrected.)
struct CorrectedCount {
  uint64_t published = 0;       ///< the counter of the last diagnostics
  uint64_t fused_corrected = 0; ///< steps whose mag status said fused "hard_iron_corrected"
};

CorrectedCount tumble_with_offset(const Eigen::Vector3d& offset_ut) {
  const auto step = make_step("{type: parallel_kf}");
  const Eigen::Vector3d field_world_ut(0.0, 20.0, -40.0);
  const double h = 1.0 / kTumbleRateHz;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();  // q_world_body, the truth
  auto rate = [](double t) -> Eigen::Vector3d {
    if (t < kTumbleRestS) {
      return Eigen::Vector3d::Zero();
    }
    const double u = t - kTumbleRestS;
    return 1.5 * Eigen::Vector3d(std::sin(0.9 * u), std::sin(0.6 * u + 1.0), std::cos(0.4 * u) - 0.3);
  };
  CorrectedCount c;
  const auto n = static_cast<uint32_t>(kTumbleRunS * kTumbleRateHz);
  for (uint32_t seq = 0; seq <= n; ++seq) {
    const double t = seq * h;
    if (seq > 0) {
      constexpr int kSub = 10;  // the truth over the step, rate at each sub-step's midpoint
      for (int j = 0; j < kSub; ++j) {
        const Eigen::Vector3d w = rate(t - h + (j + 0.5) * h / kSub);
        if (w.norm() > 0.0) {
          q = (q * Eigen::Quaterniond(Eigen::AngleAxisd(w.norm() * h / kSub, w.normalized()))).normalized();
        }
      }
    }
    ImuSample s = rest_sample(seq);
    s.gyro_rps = rate(t);
    s.accel_mps2 = q.conjugate() * Eigen::Vector3d(0.0, 0.0, 9.81);
    s.mag_ut = q.conjugate() * field_world_ut + offset_ut;
    if (!step->step(s)) {
      continue;
    }
    nodes::DiagnosticsReport report;
    step->diagnostics(report);
    const msg::FilterDiagnostics d = nodes::to_diagnostics_msg(report, step->sensor_id());
    const uint64_t now = published_counter(d, "mag_hard_iron_corrected");
    const uint64_t added = now - c.published;
    const msg::SourceStatus mag = published_source(d, "mag");
    const bool corrected = mag.fused() && mag.reason() == "hard_iron_corrected";
    EXPECT_LE(added, 1U) << "t " << t;
    if (corrected) {
      EXPECT_EQ(added, 1U) << "t " << t << ": fused corrected, not counted";
      ++c.fused_corrected;
    } else if (mag.fused() && mag.reason().to_string().empty()) {
      EXPECT_EQ(added, 0U) << "t " << t << ": fused uncorrected, counted";
    }
    c.published = now;
  }
  return c;
}

TEST(ParallelKfNode, GivenATumblingSensorWithAnAttachedMagnetWhenDiagnosedThenTheCorrectedSamplesAreCounted) {
  // GIVEN a sensor tumbling with a 30 uT offset fixed in its body, WHEN the node's step runs
  const CorrectedCount magnet = tumble_with_offset(Eigen::Vector3d(20.0, -15.0, 16.0));
  // THEN its diagnostics count the corrected steps (checked step by step inside), and there are some
  EXPECT_GT(magnet.fused_corrected, 0U) << "the estimate should converge and be applied within the run";
  EXPECT_GE(magnet.published, magnet.fused_corrected);
  // and a clean sensor gets no correction and a zero count
  const CorrectedCount clean = tumble_with_offset(Eigen::Vector3d::Zero());
  EXPECT_EQ(clean.fused_corrected, 0U);
  EXPECT_EQ(clean.published, 0U);
}

}  // namespace
}  // namespace poise::testing
