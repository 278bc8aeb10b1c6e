// Selective EKF: closed-form checks, bad input, capture-time vision and simulated scenarios
// (GIVEN/WHEN/THEN, seeded, simulated time).
#include "poise/core/consistency.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/sim/vision_synth.h"
#include "poise/eval/selective_ekf_eval.h"
#include "poise/eval/broad.h"
#include "poise/eval/imu_delay.h"
#include "poise/eval/filter_registry.h"
#include "poise/eval/runner.h"
#include "poise/testing/param_errors.h"
#include "poise/testing/testing.h"

#include "poise/sim/sensor_simulator.h"

#include <Eigen/Eigenvalues>
#include <CLI/CLI.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <deque>
#include <random>
#include <vector>

namespace poise {
namespace {

constexpr uint64_t kSeed = 7;
constexpr double kRateHz = 100.0;
// Tolerances (deg unless stated).
constexpr double kFollowVisionMaxDeg = 3.0;    // max error while the magnet is near, tag visible
constexpr double kFollowVisionRmsDeg = 1.5;
constexpr double kDisturbedGnMinDeg = 10.0;    // the magnet really corrupts q_imu (mean)
constexpr double kUntrustedFraction = 0.9;     // of the magnet hold samples
constexpr double kRecoveredTrustedFraction = 0.6;  // GN tilt errors from hand motion trip (9)
constexpr double kAngleTestQuietFraction = 0.1;  // angle test (8) failing after the magnet left
constexpr double kTagLostMaxDeg = 8.0;
constexpr double kDriftMarginDeg = 5.0;       // beyond bias x flagged time: GN leaks in during
                                               // the ramp, before the 3 deg angle test trips         // gyro + gated magnetometer over an 11 s outage
constexpr double kRateBoundRps = 0.2;          // |w - omega_true| while the tag is lost
constexpr double kSigmaBoundDeg = 20.0;        // attitude 1-sigma stays bounded
constexpr double kLatencyLiveRmsDeg = 0.5;     // live outputs, late vs on time (late lacks 80 ms)
constexpr double kLatencyEquivalenceRmsDeg = 0.15;  // truth-error RMS, late vs on time
constexpr double kLatencyFinalDeg = 1e-6;      // after the last vision is in, identical states
constexpr double kReplayExactDeg = 1e-9;
constexpr double kImuDelayCompensatedRmsDeg = 0.6;  // 20 ms IMU lag, compensated
constexpr double kImuDelayGainFactor = 3.0;          // uncompensated error at least 3x larger
constexpr double kBlockPathEquivalenceDeg = 1e-6;
constexpr double kBroadImuDelayMinS = 0.002;  // BROAD's IMU: 4.06-4.45 ms on trials 01-18
constexpr double kBroadImuDelayMaxS = 0.008;
constexpr double kBroadDelayGainDeg = 0.5;    // trial 30: 1.73 -> 0.66 deg measured

// ------------------------------------------------------------------ scenario runner
struct Episode {
  double start_s = 10.0;  // magnet starts approaching
  double ramp_s = 2.0;
  double hold_s = 10.0;
};

sim::SimConfig handheld_with_magnet(const Episode& e, double duration_s = 40.0) {
  sim::SimConfig c = sim::make_scenario("random_motion", kRateHz, kSeed);
  sim::MotionSegment walk;
  walk.name = "handheld";
  walk.duration_s = duration_s;
  walk.rotation_amplitude_rps = 0.8;
  walk.rotation_freq_hz = 0.25;
  walk.level_gain_per_s = 0.5;
  walk.accel_amplitude_mps2 = 1.5;
  walk.accel_freq_hz = 0.8;
  sim::MotionSegment rest;  // a start-up rest, as in BROAD: the dip reference is learnt here
  rest.duration_s = 3.0;
  walk.duration_s = duration_s - rest.duration_s;
  c.segments = {rest, walk};
  c.duration_s = duration_s;
  sim::MagnetEpisode near;
  near.start_s = e.start_s;
  near.ramp_s = e.ramp_s;
  near.hold_s = e.hold_s;
  near.field_ut = Eigen::Vector3d(30.0, 10.0, -20.0);  // ~37 uT, world-fixed (a magnet on a desk)
  c.magnets = {near};
  return c;
}

struct Step {
  double t_s = 0.0;
  double err_deg = 0.0;     // filter vs truth
  double gn_err_deg = 0.0;  // Gauss-Newton q_imu vs truth
  bool mag_trusted = true;
  bool angle_failed = false;  // disturbance tests: dip (8) or |m|
  Decision imu_quat = Decision::kNone;
  double rate_err_rps = 0.0;
  double sigma_deg = 0.0;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
};

struct RunOptions {
  SelectiveEkfParams params;
  VisionSynthParams vision;
  bool vision_enabled = true;
  double hide_from_s = -1.0;  // tag lost in [hide_from_s, hide_to_s)
  double hide_to_s = -1.0;
  bool stamp_at_arrival = false;  // the wrong way: pretend a late frame is current
  int imu_lag_samples = 0;  // the IMU reports the motion this many samples late (its DLPF)
};

std::vector<Step> run(const sim::SimConfig& cfg, const RunOptions& o) {
  sim::SensorSimulator simu(cfg);
  SelectiveEkf ekf(o.params);
  GaussNewton gn(ekf.params().gauss_newton);  // the paper's q_imu, for reference (kSplit skips it)
  VisionSynthesizer synth(o.vision);
  std::vector<Step> out;
  std::deque<ImuSample> lagged;  // IMU samples waiting out the sensor's group delay
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    const bool hidden = s.truth.t_s >= o.hide_from_s && s.truth.t_s < o.hide_to_s;
    synth.push_truth(s.imu.stamp_ns, s.truth.q_world_body, s.truth.p_world_m, !hidden);
    lagged.push_back(s.imu);
    if (lagged.size() <= static_cast<size_t>(o.imu_lag_samples)) {
      continue;  // start-up: the first reading is not out yet
    }
    ImuSample reading = lagged.front();  // the motion of imu_lag_samples ago, stamped now
    lagged.pop_front();
    reading.stamp_ns = s.imu.stamp_ns;
    ekf.update_imu(reading);
    gn.update(reading);
    for (VisionPose v : synth.pop_arrived(s.imu.stamp_ns)) {
      if (o.stamp_at_arrival) {
        v.capture_stamp_ns = s.imu.stamp_ns;
      }
      if (o.vision_enabled) {
        ekf.update_vision(v);
      }
    }
    Step st;
    st.t_s = s.truth.t_s;
    st.q = ekf.q_world_body();
    st.err_deg = quat_angle_between(st.q, s.truth.q_world_body) * kDegPerRad;
    st.gn_err_deg = quat_angle_between(gn.result().q_world_body, s.truth.q_world_body) * kDegPerRad;
    st.mag_trusted = ekf.mag_status().trusted;
    st.angle_failed = ekf.mag_status().angle_test_failed || ekf.mag_status().norm_test_failed;
    st.imu_quat = ekf.status(SelectiveEkfAid::kImuQuat).last;
    st.rate_err_rps = (ekf.state().w_rps - s.truth.omega_body_rps).norm();
    st.sigma_deg = ekf.attitude_sigma_deg().maxCoeff();
    out.push_back(st);
  }
  return out;
}

struct Window {
  double max_err = 0.0;
  double rms_err = 0.0;
  double mean_gn_err = 0.0;
  double trusted_fraction = 0.0;
  double angle_failed_fraction = 0.0;
  double max_rate_err = 0.0;
  double max_sigma = 0.0;
  int n = 0;
};

Window window(const std::vector<Step>& steps, double from_s, double to_s) {
  Window w;
  double sq = 0.0;
  double gn = 0.0;
  int trusted = 0;
  int angle_failed = 0;
  for (const Step& s : steps) {
    if (s.t_s < from_s || s.t_s >= to_s) {
      continue;
    }
    ++w.n;
    w.max_err = std::max(w.max_err, s.err_deg);
    sq += s.err_deg * s.err_deg;
    gn += s.gn_err_deg;
    trusted += s.mag_trusted ? 1 : 0;
    angle_failed += s.angle_failed ? 1 : 0;
    w.max_rate_err = std::max(w.max_rate_err, s.rate_err_rps);
    w.max_sigma = std::max(w.max_sigma, s.sigma_deg);
  }
  if (w.n > 0) {
    w.rms_err = std::sqrt(sq / w.n);
    w.mean_gn_err = gn / w.n;
    w.trusted_fraction = static_cast<double>(trusted) / w.n;
    w.angle_failed_fraction = static_cast<double>(angle_failed) / w.n;
  }
  return w;
}

VisionSynthParams tag(double latency_ms) {
  VisionSynthParams v;
  v.rate_hz = 30.0;
  v.latency_ms = latency_ms;
  v.noise_deg = 1.0;
  v.noise_m = 0.01;
  v.seed = kSeed;
  return v;
}

ImuSample level_sample(int64_t stamp_ns) {
  ImuSample s;
  s.stamp_ns = stamp_ns;
  s.accel_mps2 = Eigen::Vector3d(0, 0, 9.81);
  s.gyro_rps = Eigen::Vector3d(0, 0, 0);
  const double dip = 60.0 * kRadPerDeg;
  s.mag_ut = 50.0 * Eigen::Vector3d(0.0, std::cos(dip), -std::sin(dip));
  s.has_mag = true;
  return s;
}

// ------------------------------------------------------------------ scenarios
TEST(SelectiveEkfScenario, GivenTagVisibleWhenMagnetNearThenFollowsVisionAndRecovers) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  // GIVEN a handheld device, tag visible at 30 Hz (50 ms latency), a magnet 10-24 s
  const Episode e;
  RunOptions o;
  o.vision = tag(50.0);
  // WHEN the filter runs through the episode
  const auto steps = run(handheld_with_magnet(e), o);
  // THEN while the magnet is at full strength the attitude follows vision and the magnetometer
  // is untrusted, although Gauss-Newton is clearly off
  const Window hold = window(steps, e.start_s + e.ramp_s, e.start_s + e.ramp_s + e.hold_s);
  EXPECT_GT(hold.mean_gn_err, kDisturbedGnMinDeg);
  EXPECT_LT(hold.max_err, kFollowVisionMaxDeg);
  EXPECT_LT(hold.rms_err, kFollowVisionRmsDeg);
  EXPECT_LT(hold.trusted_fraction, 1.0 - kUntrustedFraction);
  EXPECT_GT(hold.angle_failed_fraction, kUntrustedFraction);
  // AND after the magnet has left the angle test is quiet and the magnetometer trusted again
  // (except where hand motion corrupts the Gauss-Newton tilt and trips the quaternion test)
  const double gone_s = e.start_s + 2.0 * e.ramp_s + e.hold_s + 1.0;
  const Window after = window(steps, gone_s, 40.0);
  EXPECT_LT(after.angle_failed_fraction, kAngleTestQuietFraction);
  EXPECT_GT(after.trusted_fraction, kRecoveredTrustedFraction);
  std::printf("hold: rms %.2f max %.2f deg, GN %.1f deg, trusted %.3f; after: trusted %.3f, "
              "angle test failing %.3f\n",
              hold.rms_err, hold.max_err, hold.mean_gn_err, hold.trusted_fraction,
              after.trusted_fraction, after.angle_failed_fraction);
  EXPECT_LT(after.max_err, kFollowVisionMaxDeg);
}

TEST(SelectiveEkfScenario, GivenStaticDeviceWhenMagnetApproachesThenFlaggedAndGyroCarries) {
  // GIVEN the simulator's static_magnet scenario (magnet 15-36 s, second weaker one 50-71 s),
  // no vision, default gating (both tests, q_imu inflated while untrusted)
  sim::SimConfig cfg = sim::make_scenario("static_magnet", kRateHz, kSeed);
  cfg.duration_s = 45.0;
  const SelectiveEkfParams p;
  sim::SensorSimulator simu(cfg);
  SelectiveEkf ekf(p);
  int hold_n = 0;
  int hold_flagged = 0;
  int clean_n = 0;
  int clean_flagged = 0;
  double max_err_deg = 0.0;
  int angle_flags = 0;
  while (!simu.done()) {
    const auto s = simu.next();
    ekf.update_imu(s.imu);
    const double t = s.truth.t_s;
    const bool flagged = !ekf.mag_status().trusted;
    // (the field moved at rest is refused before the gate's tests: flagged by it instead)
    angle_flags += ekf.mag_status().angle_test_failed || ekf.mag_status().moved_at_rest ? 1 : 0;
    if (t >= 18.0 && t < 33.0) {
      ++hold_n;
      hold_flagged += flagged ? 1 : 0;
    } else if ((t >= 2.0 && t < 14.0) || t >= 38.0) {
      ++clean_n;
      clean_flagged += flagged ? 1 : 0;
    }
    max_err_deg = std::max(
        max_err_deg, quat_angle_between(ekf.q_world_body(), s.truth.q_world_body) * kDegPerRad);
  }
  // THEN the magnet is flagged throughout its hold and not outside it, and the attitude (gyro
  // only while flagged; uncalibrated bias |b| = 0.44 deg/s) stays within the drift bound
  EXPECT_GT(static_cast<double>(hold_flagged) / hold_n, kUntrustedFraction);
  EXPECT_LT(static_cast<double>(clean_flagged) / clean_n, 1.0 - kUntrustedFraction);
  const double bias_dps = cfg.noise.gyro_bias_rps.norm() * kDegPerRad;
  const double flagged_s = 2.0 * cfg.magnets[0].ramp_s + cfg.magnets[0].hold_s;
  EXPECT_LT(max_err_deg, bias_dps * flagged_s + kDriftMarginDeg);
  EXPECT_GT(angle_flags, hold_n / 2);  // the disturbance angle (8) or the field moved at rest sees this magnet
  std::printf("hold flagged %.3f, clean flagged %.3f, angle-test flags %d, max error %.2f deg\n",
              static_cast<double>(hold_flagged) / hold_n,
              static_cast<double>(clean_flagged) / clean_n, angle_flags, max_err_deg);
}

TEST(SelectiveEkfScenario, GivenTagLostDuringDisturbanceWhenGatedThenGyroCarriesAttitude) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  // GIVEN the magnet episode and the tag lost from 11 s to 22 s (inside the disturbance)
  const Episode e;
  RunOptions o;
  o.vision = tag(50.0);
  o.hide_from_s = 11.0;
  o.hide_to_s = 22.0;
  // WHEN run with gating and without
  const auto gated = run(handheld_with_magnet(e), o);
  RunOptions off = o;
  off.params.gating_enabled = false;
  const auto ungated = run(handheld_with_magnet(e), off);
  // THEN the gated filter stays within the gyro-drift bound, its rate and covariance stay
  // bounded, and it beats the ungated filter clearly
  const Window g = window(gated, o.hide_from_s, o.hide_to_s);
  const Window u = window(ungated, o.hide_from_s, o.hide_to_s);
  EXPECT_LT(g.max_err, kTagLostMaxDeg);
  EXPECT_LT(g.max_rate_err, kRateBoundRps);
  EXPECT_LT(g.max_sigma, kSigmaBoundDeg);
  EXPECT_GT(u.max_err, 2.0 * g.max_err);
  // AND when the tag is back the error returns to the vision level
  const Window back = window(gated, o.hide_to_s + 1.0, 40.0);
  EXPECT_LT(back.max_err, kFollowVisionMaxDeg);
}

TEST(SelectiveEkfScenario, GivenVision80msLateWhenAppliedAtCaptureThenSameAsOnTime) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  // GIVEN identical runs (same noise draws) with vision on time and 80 ms late
  const Episode e;
  const sim::SimConfig cfg = handheld_with_magnet(e, 30.0);
  RunOptions on_time;
  on_time.vision = tag(0.0);
  // the replay mechanics with exact stamps (the online time-offset estimate would compensate the
  // naive run too: VisionTimeOffset.* tests that)
  on_time.params.vision_time_offset_sigma_s = 0.0;
  RunOptions late = on_time;
  late.vision = tag(80.0);
  RunOptions naive = late;
  naive.stamp_at_arrival = true;
  // WHEN each is run
  const auto a = run(cfg, on_time);
  const auto b = run(cfg, late);
  const auto c = run(cfg, naive);
  // THEN the late run tracks the on-time run (it lacks only the newest 80 ms of vision)...
  ASSERT_EQ(a.size(), b.size());
  double sq = 0.0;
  int n = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].t_s < 1.0) {
      continue;
    }
    const double d = quat_angle_between(a[i].q, b[i].q) * kDegPerRad;
    sq += d * d;
    ++n;
  }
  EXPECT_LT(std::sqrt(sq / n), kLatencyLiveRmsDeg);
  // ... its truth error matches the on-time one, and beats applying frames at arrival
  const Window wa = window(a, 1.0, 30.0);
  const Window wb = window(b, 1.0, 30.0);
  const Window wc = window(c, 1.0, 30.0);
  EXPECT_NEAR(wb.rms_err, wa.rms_err, kLatencyEquivalenceRmsDeg);
  EXPECT_GT(wc.rms_err, wb.rms_err + kLatencyEquivalenceRmsDeg);
  std::printf("truth-error RMS deg: on time %.3f, 80 ms late %.3f, applied at arrival %.3f; "
              "live late-vs-on-time RMS %.3f\n",
              wa.rms_err, wb.rms_err, wc.rms_err, std::sqrt(sq / n));
}

// ------------------------------------------------------------------ capture-time mechanics
TEST(SelectiveEkfScenario, GivenImuGroupDelayWhenConfiguredThenOutputAtTheStampIsCloser) {
  // GIVEN a handheld device whose IMU reports the motion 3 samples (30 ms) late (a low-pass
  // filter in the sensor), brisk rotation without linear acceleration (Gauss-Newton is then
  // accurate), no tag, no magnet: the lag is the dominant error
  Episode none;
  none.start_s = 100.0;  // after the end: no magnet
  sim::SimConfig cfg = handheld_with_magnet(none, 30.0);
  cfg.segments.back().accel_amplitude_mps2 = 0.0;
  cfg.segments.back().rotation_amplitude_rps = 2.0;
  RunOptions plain;
  plain.vision_enabled = false;
  plain.imu_lag_samples = 3;
  RunOptions compensated = plain;
  compensated.params.imu_delay_s = 3.0 / kRateHz;
  // WHEN the filter runs with and without imu_delay_s
  const Window a = window(run(cfg, plain), 5.0, 30.0);
  const Window b = window(run(cfg, compensated), 5.0, 30.0);
  std::printf("truth-error RMS at the sample stamps: imu_delay_s 0 -> %.3f deg, 0.03 -> %.3f deg\n",
              a.rms_err, b.rms_err);
  // THEN the compensated output (run at stamp - delay, predicted to the stamp) is clearly closer
  // to the truth at the stamp, and the uncompensated filter shows the lag
  EXPECT_LT(b.rms_err, kImuDelayCompensatedRmsDeg);
  EXPECT_GT(a.rms_err, b.rms_err * kImuDelayGainFactor);
}

TEST(SelectiveEkfVision, GivenImuDelayWhenOutputThenStatePredictedByTheEstimatedRate) {
  // GIVEN a filter with a 5 ms IMU delay, rotating about z at 1 rad/s
  SelectiveEkfParams p;
  p.imu_delay_s = 0.005;
  p.output_max_correction_dps = 0.0;  // the output is the state's prediction itself
  SelectiveEkf ekf(p);
  for (int k = 0; k < 200; ++k) {
    ImuSample s = level_sample(int64_t{1'000'000'000} + k * int64_t{10'000'000});
    s.gyro_rps = Eigen::Vector3d(0.0, 0.0, 1.0);
    // the magnetometer turns with the device (consistent with the gyro)
    s.mag_ut = quat_exp(Eigen::Vector3d(0.0, 0.0, 0.01 * k)).conjugate() * s.mag_ut;
    ekf.update_imu(s);
  }
  // THEN q_world_body() = state (x) exp(w * delay), and the state itself is not advanced
  const Eigen::Quaterniond predicted =
      (ekf.state().q_world_body * quat_exp(ekf.state().w_rps * 0.005)).normalized();
  EXPECT_LT(quat_angle_between(ekf.q_world_body(), predicted), kReplayExactDeg * kRadPerDeg);
  EXPECT_NEAR(ekf.state().w_rps.z(), 1.0, 0.01);
  EXPECT_NEAR(quat_angle_between(ekf.q_world_body(), ekf.state().q_world_body) * kDegPerRad,
              0.005 * kDegPerRad, 0.01);
  // AND the state runs at stamp - delay
  EXPECT_EQ(ekf.state().stamp_ns, int64_t{1'000'000'000} + 199 * int64_t{10'000'000} - 5'000'000);
  // AND an out-of-range delay is refused
  SelectiveEkfParams bad;
  bad.imu_delay_s = 0.2;
  EXPECT_THROW(SelectiveEkf{bad}, std::invalid_argument);
}

// The default: no delay known (imu_delay_s NaN, as the parallel KF's): half a sample, the least
// delay any sampled sensor has. Oracles: the stamps (the state at the interval's middle), the
// state predicted over half a sample with its rate, and the guess's error (dt^2 / 12) w_z^2 on the
// heading variance against a filter configured with that half sample.
TEST(SelectiveEkfVision, GivenNoDelayKnownWhenRunThenTheStateIsAtTheIntervalsMiddleAndTheOutputPredictedOverHalfASample) {
  constexpr int64_t kStepNs = 10'000'000;  // 100 Hz
  constexpr double kDtS = 0.01;
  // of the term: the two filters differ besides it by their first interval (the unknown delay's
  // first sample has no interval, so its state starts at the stamp, the other's 5 ms before): 5 %
  constexpr double kVarRelTol = 0.1;
  // 10 s: the low-pass has forgotten the start (which the estimate's error covariance correlates
  // with the attitude's tilt) and the field is verified, so the two differ by their first
  // interval no more than the tolerance
  constexpr int kSamples = 1000;
  auto feed = [](SelectiveEkf& ekf) {
    for (int k = 0; k < kSamples; ++k) {
      ImuSample s = level_sample(int64_t{1'000'000'000} + k * kStepNs);
      s.gyro_rps = Eigen::Vector3d(0.0, 0.0, 1.0);
      s.mag_ut = quat_exp(Eigen::Vector3d(0.0, 0.0, 0.01 * k)).conjugate() * s.mag_ut;
      ASSERT_TRUE(ekf.update_imu(s));
    }
  };
  // GIVEN the defaults (delay not known) and the same filter told half a sample
  SelectiveEkfParams p;
  ASSERT_TRUE(std::isnan(p.imu_delay_s));
  p.output_max_correction_dps = 0.0;  // the output is the state's prediction itself
  SelectiveEkfParams half = p;
  half.imu_delay_s = 0.5 * kDtS;
  SelectiveEkf unknown(p);
  SelectiveEkf known(half);
  // WHEN both run (1 rad/s about z)
  feed(unknown);
  feed(known);
  // THEN the state runs at the interval's middle, the output is predicted over half a sample
  EXPECT_EQ(unknown.state().stamp_ns, int64_t{1'000'000'000} + (kSamples - 1) * kStepNs - kStepNs / 2);
  const Eigen::Quaterniond predicted =
      (unknown.state().q_world_body * quat_exp(unknown.state().w_rps * 0.5 * kDtS)).normalized();
  EXPECT_LT(quat_angle_between(unknown.q_world_body(), predicted), kReplayExactDeg * kRadPerDeg);
  // AND the published covariance carries the guess's error about the rate axis (world z)
  const double w_z = (unknown.state().q_world_body * unknown.state().w_rps).z();
  const double added = unknown.attitude_covariance()(2, 2) - known.attitude_covariance()(2, 2);
  std::printf("delay not known: heading variance + %.3g rad^2 (dt^2 / 12 w^2 = %.3g)\n", added,
              kDtS * kDtS / 12.0 * w_z * w_z);
  const double term = kDtS * kDtS / 12.0 * w_z * w_z;
  EXPECT_NEAR(added, term, kVarRelTol * term);
  // AND null in YAML is "not known"
  const std::string path = ::testing::TempDir() + "/sekf_delay_null.yaml";
  std::ofstream(path) << "selective_ekf:\n  imu_delay_s: null\n";
  EXPECT_TRUE(std::isnan(load_selective_ekf_params(path).imu_delay_s));
}

// As the parallel KF's adapter: a delay the IMU's driver publishes (`poise process --filter`
// offers the recorded imu_info) is taken unless the configuration set one; a running filter
// restarts on it (its state's time is the stamp minus the delay).
TEST(SelectiveEkfConfig, GivenNoConfiguredDelayWhenTheDriverPublishesOneThenItIsTakenElseTheConfiguredOneWins) {
  constexpr double kPublishedS = 0.0048;  // oracle: the delay offered
  SelectiveEkfFilter unknown;
  SelectiveEkfParams zero;
  zero.imu_delay_s = 0.0;
  SelectiveEkfFilter configured_zero(zero);
  EXPECT_TRUE(unknown.take_published_imu_delay(kPublishedS));
  EXPECT_DOUBLE_EQ(unknown.core().params().imu_delay_s, kPublishedS);
  ASSERT_TRUE(unknown.update(level_sample(1'000'000'000)));
  EXPECT_TRUE(unknown.take_published_imu_delay(0.003));  // a later one replaces it, the filter restarts
  EXPECT_DOUBLE_EQ(unknown.core().params().imu_delay_s, 0.003);
  EXPECT_FALSE(unknown.initialized());
  EXPECT_FALSE(configured_zero.take_published_imu_delay(kPublishedS));
  EXPECT_DOUBLE_EQ(configured_zero.core().params().imu_delay_s, 0.0);
  EXPECT_THROW(unknown.take_published_imu_delay(0.2), std::invalid_argument);
}

// A camera's per-detection covariance is taken whole (issue 31): a floor tag fixes the heading far
// better than the tilt. Oracles: the first frame resets the attitude with the frame's covariance,
// which for a pose yawed 90 deg is the world matrix with x and y swapped in the body frame; the
// camera's 6x6 [position | rotation] reaches it through to_vision_pose; a covariance that is not
// one is rejected and counted.
TEST(SelectiveEkfVision, GivenAFrameWithItsOwnAnisotropicCovarianceWhenFusedThenTheBodyFrameCovarianceIsItsRotation) {
  constexpr double kTolRad2 = 1e-12;  // rad^2: the same numbers through a rotation
  const double sx = 0.2 * kRadPerDeg;
  const double sy = 0.1 * kRadPerDeg;
  const double sz = 0.02 * kRadPerDeg;  // the heading, ten times better than the tilt
  SelectiveEkfParams p;
  p.imu_delay_s = 0.0;
  p.vision_time_offset_sigma_s = 0.0;  // stamps exact: the covariance is the camera's alone
  SelectiveEkf f(p);
  for (int k = 0; k <= 10; ++k) {
    ASSERT_TRUE(f.update_imu(level_sample(1'000'000'000 + k * 10'000'000LL)));
  }
  CameraPoseMeasurement cam;
  cam.stamp_ns = 1'000'000'000 + 10 * 10'000'000LL;
  cam.q_world_camera = quat_from_euler_zyx(0.0, 0.0, 90.0 * kRadPerDeg);  // q_body_camera identity
  cam.covariance.setZero();
  cam.covariance.topLeftCorner<3, 3>() = Eigen::Matrix3d::Identity() * 1e-4;
  cam.covariance.bottomRightCorner<3, 3>() = Eigen::Vector3d(sx * sx, sy * sy, sz * sz).asDiagonal();
  const VisionPose v = to_vision_pose(cam);
  ASSERT_NEAR((v.attitude_covariance_world - cam.covariance.bottomRightCorner<3, 3>()).cwiseAbs().maxCoeff(), 0.0,
              kTolRad2);
  ASSERT_TRUE(f.update_vision(v));
  const Eigen::Matrix3d p_th = f.state().P.block<3, 3>(SelectiveEkf::kTh, SelectiveEkf::kTh);
  EXPECT_NEAR(p_th(0, 0), sy * sy, kTolRad2);  // body x is world y at yaw 90 deg
  EXPECT_NEAR(p_th(1, 1), sx * sx, kTolRad2);
  EXPECT_NEAR(p_th(2, 2), sz * sz, kTolRad2);
  // AND a second frame, fused: each principal axis by its own variance, so the heading's variance
  // stays near sz^2 where the isotropic mean (sqrt of the mean variance, 0.13 deg) would leave it
  VisionPose v2 = v;
  v2.capture_stamp_ns += 10'000'000;
  ASSERT_TRUE(f.update_imu(level_sample(v2.capture_stamp_ns)));
  ASSERT_TRUE(f.update_vision(v2));
  const double heading_var = f.state().P(SelectiveEkf::kTh + 2, SelectiveEkf::kTh + 2);
  EXPECT_LT(heading_var, sz * sz);
  // AND a matrix that is not a covariance is refused and counted
  VisionPose bad = v2;
  bad.capture_stamp_ns += 1;
  bad.attitude_covariance_world(0, 0) = -1e-6;
  EXPECT_FALSE(f.update_vision(bad));
  bad.attitude_covariance_world = v.attitude_covariance_world;
  bad.attitude_covariance_world(1, 2) = std::nan("");
  EXPECT_FALSE(f.update_vision(bad));
  EXPECT_EQ(f.vision_counters().bad_input, 2U);
}

TEST(SelectiveEkfVision, GivenNoLeverArmWhenBlockPathUsedThenSameAsTheFullCovariancePath) {
  // GIVEN the same run twice: a zero lever arm (attitude and position blocks updated separately)
  // and a 1 nm lever arm (any lever couples the blocks: the full 12-state path)
  Episode e;
  const sim::SimConfig cfg = handheld_with_magnet(e, 20.0);
  RunOptions blocks;
  blocks.vision = tag(50.0);
  RunOptions full = blocks;
  full.params.p_body_camera_m = Eigen::Vector3d(1e-9, 0.0, 0.0);
  const auto a = run(cfg, blocks);
  const auto b = run(cfg, full);
  ASSERT_EQ(a.size(), b.size());
  // THEN the estimates agree to round-off (the 1 nm lever moves the position by 1 nm only)
  double worst = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, quat_angle_between(a[i].q, b[i].q) * kDegPerRad);
  }
  EXPECT_LT(worst, kBlockPathEquivalenceDeg);
}

TEST(SelectiveEkfVision, GivenLateVisionWhenAllArrivedThenStateEqualsOnTimeProcessing) {
  // GIVEN two filters fed the same IMU stream and the same frames, one on time, one 80 ms late
  const sim::SimConfig cfg = handheld_with_magnet(Episode{}, 6.0);
  sim::SensorSimulator simu(cfg);
  const auto samples = simu.run();
  // exact stamps: the online time-offset estimate uses each frame at its arrival, so only a
  // filter that takes the stamps as exact replays late frames into the on-time state exactly
  SelectiveEkfParams exact;
  exact.vision_time_offset_sigma_s = 0.0;
  exact.imu_delay_s = 0.0;  // the simulator samples the motion at the stamp: frames at IMU stamps are on time
  SelectiveEkf on_time(exact);
  SelectiveEkf late(exact);
  VisionSynthesizer s1(tag(0.0));
  VisionSynthesizer s2(tag(80.0));
  for (const auto& s : samples) {
    s1.push_truth(s.imu.stamp_ns, s.truth.q_world_body, s.truth.p_world_m, true);
    s2.push_truth(s.imu.stamp_ns, s.truth.q_world_body, s.truth.p_world_m, true);
    on_time.update_imu(s.imu);
    late.update_imu(s.imu);
    for (const auto& v : s1.pop_arrived(s.imu.stamp_ns)) {
      on_time.update_vision(v);
    }
    for (const auto& v : s2.pop_arrived(s.imu.stamp_ns)) {
      late.update_vision(v);
    }
  }
  // WHEN the last late frame (captured <= end - 80 ms) is in, compare the state at a time when
  // both have seen the same frames: replay makes the late filter identical at the end only if
  // no frame is still in flight, so drain it by advancing both without new frames.
  int64_t t = samples.back().imu.stamp_ns;
  for (int k = 0; k < 10; ++k) {
    t += 10'000'000;
    ImuSample s = samples.back().imu;
    s.stamp_ns = t;
    on_time.update_imu(s);
    late.update_imu(s);
    for (const auto& v : s2.pop_arrived(t)) {
      late.update_vision(v);
    }
  }
  // THEN both states agree to round-off and the late one replayed samples
  EXPECT_LT(quat_angle_between(on_time.state_output(), late.state_output()) * kDegPerRad,
            kLatencyFinalDeg);
  EXPECT_LT((on_time.state().w_rps - late.state().w_rps).norm(), 1e-9);
  EXPECT_LT((on_time.state().P - late.state().P).norm(), 1e-9);
  EXPECT_GT(late.vision_counters().replayed_imu_samples, 0u);
  EXPECT_EQ(late.vision_counters().applied, on_time.vision_counters().applied);
}

TEST(SelectiveEkfVision, GivenOutOfOrderFramesWhenReplayedThenEqualsInOrderAndCounted) {
  // GIVEN 2 s of level IMU samples and two vision frames captured 30 ms apart
  auto make = [] {
    SelectiveEkf f;
    for (int k = 0; k <= 200; ++k) {
      f.update_imu(level_sample(1'000'000'000 + k * 10'000'000LL));
    }
    return f;
  };
  VisionPose v1;
  v1.capture_stamp_ns = 1'000'000'000 + 150 * 10'000'000LL;
  v1.q_world_camera = quat_from_euler_zyx(0.01, -0.02, 0.03);
  v1.p_world_camera_m = Eigen::Vector3d(0.1, 0.2, 0.3);
  VisionPose v2 = v1;
  v2.capture_stamp_ns += 30'000'000;
  v2.q_world_camera = quat_from_euler_zyx(0.012, -0.018, 0.035);
  SelectiveEkf in_order = make();
  SelectiveEkf reversed = make();
  // WHEN fed in order to one filter and reversed to the other
  ASSERT_TRUE(in_order.update_vision(v1));
  ASSERT_TRUE(in_order.update_vision(v2));
  ASSERT_TRUE(reversed.update_vision(v2));
  ASSERT_TRUE(reversed.update_vision(v1));
  // THEN the states are identical and the reversed one counted an out-of-order frame
  EXPECT_LT(quat_angle_between(in_order.state_output(), reversed.state_output()) * kDegPerRad,
            kReplayExactDeg);
  EXPECT_LT((in_order.state().P - reversed.state().P).norm(), 1e-12);
  EXPECT_EQ(in_order.vision_counters().out_of_order, 0u);
  EXPECT_EQ(reversed.vision_counters().out_of_order, 1u);
}

TEST(SelectiveEkfVision, GivenFrameOlderThanHistoryWhenReceivedThenRejectedAsTooOld) {
  SelectiveEkfParams p;
  p.history_s = 0.2;
  SelectiveEkf f(p);
  for (int k = 0; k <= 100; ++k) {
    f.update_imu(level_sample(1'000'000'000 + k * 10'000'000LL));
  }
  const Eigen::Quaterniond before = f.q_world_body();
  VisionPose v;
  v.capture_stamp_ns = 1'000'000'000 + 70 * 10'000'000LL;  // 0.3 s old
  EXPECT_FALSE(f.update_vision(v));
  EXPECT_EQ(f.vision_counters().too_old, 1u);
  EXPECT_EQ(f.status(SelectiveEkfAid::kVisionAttitude).last, Decision::kRejectedTooOld);
  EXPECT_EQ(quat_angle_between(before, f.q_world_body()), 0.0);
}

TEST(SelectiveEkfVision, GivenFutureFrameWhenImuCatchesUpThenAppliedAtItsStamp) {
  SelectiveEkf f;
  for (int k = 0; k <= 100; ++k) {
    f.update_imu(level_sample(1'000'000'000 + k * 10'000'000LL));
  }
  VisionPose v;
  v.capture_stamp_ns = 1'000'000'000 + 105 * 10'000'000LL + 5'000'000;  // between samples
  v.q_world_camera = quat_from_euler_zyx(0.0, 0.0, 0.05);
  ASSERT_TRUE(f.update_vision(v));
  EXPECT_EQ(f.vision_counters().future, 1u);
  EXPECT_EQ(f.status(SelectiveEkfAid::kVisionAttitude).last, Decision::kNone);
  for (int k = 101; k <= 106; ++k) {
    f.update_imu(level_sample(1'000'000'000 + k * 10'000'000LL));
  }
  EXPECT_EQ(f.status(SelectiveEkfAid::kVisionAttitude).last, Decision::kReset);  // first frame aligns
  EXPECT_EQ(f.status(SelectiveEkfAid::kVisionAttitude).last_fused_stamp_ns, v.capture_stamp_ns);
}

TEST(SelectiveEkfVision, GivenNegatedQuaternionWhenFusedThenSameAsPositive) {
  auto make = [] {
    SelectiveEkfParams p;
    p.imu_delay_s = 0.0;  // the samples describe the stamp: the frame at the last one is on time
    SelectiveEkf f(p);
    for (int k = 0; k <= 100; ++k) {
      f.update_imu(level_sample(1'000'000'000 + k * 10'000'000LL));
    }
    VisionPose v0;
    v0.capture_stamp_ns = 1'000'000'000 + 100 * 10'000'000LL;
    f.update_vision(v0);  // align
    return f;
  };
  SelectiveEkf a = make();
  SelectiveEkf b = make();
  VisionPose v;
  v.capture_stamp_ns = 1'000'000'000 + 100 * 10'000'000LL;
  v.q_world_camera = quat_from_euler_zyx(0.01, 0.02, -0.01);
  VisionPose vn = v;
  vn.q_world_camera.coeffs() = -v.q_world_camera.coeffs();
  a.update_vision(v);
  b.update_vision(vn);
  EXPECT_EQ(a.status(SelectiveEkfAid::kVisionAttitude).last, Decision::kFused);
  EXPECT_LT(quat_angle_between(a.state_output(), b.state_output()) * kDegPerRad, kReplayExactDeg);
  EXPECT_GT(quat_angle_between(a.state_output(), Eigen::Quaterniond::Identity()), 0.0);
}

// ------------------------------------------------------------------ bad input
TEST(SelectiveEkfInput, GivenBadImuSamplesWhenFedThenRejectedCountedAndStateUntouched) {
  SelectiveEkf f;
  int64_t t = 1'000'000'000;
  for (int k = 0; k < 50; ++k, t += 10'000'000) {
    ASSERT_TRUE(f.update_imu(level_sample(t)));
  }
  const SelectiveEkfState before = f.state();
  ImuSample nan_gyro = level_sample(t);
  nan_gyro.gyro_rps.x() = std::numeric_limits<double>::quiet_NaN();
  ImuSample zero_acc = level_sample(t);
  zero_acc.accel_mps2.setZero();
  ImuSample old = level_sample(t - 20'000'000);
  EXPECT_FALSE(f.update_imu(nan_gyro));
  EXPECT_FALSE(f.update_imu(zero_acc));
  EXPECT_FALSE(f.update_imu(old));
  EXPECT_EQ(f.imu_rejections().count(RejectReason::kNonFiniteGyro), 1u);
  EXPECT_EQ(f.imu_rejections().count(RejectReason::kZeroAccel), 1u);
  EXPECT_EQ(f.imu_rejections().count(RejectReason::kNonMonotonicStamp), 1u);
  EXPECT_EQ(f.state().stamp_ns, before.stamp_ns);
  EXPECT_EQ((f.state().P - before.P).norm(), 0.0);
  // A NaN magnetometer keeps the sample (gyro, accelerometer tilt) but gives no heading row.
  // (tilt and heading are fused every aiding_period_s: feed NaN magnetometers for longer)
  const int nan_samples = 1 + static_cast<int>(f.params().aiding_period_s / 0.01);
  for (int k = 0; k < nan_samples; ++k) {
    t += 10'000'000;
    ImuSample nan_mag = level_sample(t);
    nan_mag.mag_ut.y() = std::numeric_limits<double>::quiet_NaN();
    EXPECT_TRUE(f.update_imu(nan_mag));
  }
  EXPECT_EQ(f.imu_rejections().count(RejectReason::kNonFiniteMag), static_cast<uint64_t>(nan_samples));
  EXPECT_EQ(f.status(SelectiveEkfAid::kMagHeading).last, Decision::kRejectedNoMag);
  EXPECT_EQ(f.status(SelectiveEkfAid::kAccelTilt).last, Decision::kFused);
  // A huge gap re-anchors time without integrating across it, once a second sample agrees.
  t += 10'000'000;
  EXPECT_FALSE(f.update_imu(level_sample(t + 5'000'000'000LL)));
  EXPECT_EQ(f.imu_rejections().count(RejectReason::kTimeGap), 1u);
  EXPECT_FALSE(f.update_imu(level_sample(t + 5'010'000'000LL)));
  EXPECT_EQ(f.imu_rejections().count(RejectReason::kTimeGap), 2u);
  EXPECT_TRUE(f.update_imu(level_sample(t + 5'020'000'000LL)));
  EXPECT_TRUE(f.state().P.allFinite());
  EXPECT_LT(f.attitude_sigma_deg().maxCoeff(), 15.0);
}

TEST(SelectiveEkfInput, GivenBadVisionWhenFedThenRejectedAndCounted) {
  SelectiveEkf f;
  VisionPose early;
  early.capture_stamp_ns = 1'000'000'000;
  EXPECT_FALSE(f.update_vision(early));  // before the first IMU sample
  EXPECT_EQ(f.vision_counters().before_init, 1u);
  for (int k = 0; k <= 50; ++k) {
    f.update_imu(level_sample(1'000'000'000 + k * 10'000'000LL));
  }
  VisionPose nan_q;
  nan_q.capture_stamp_ns = 1'400'000'000;
  nan_q.q_world_camera.coeffs()(0) = std::numeric_limits<double>::quiet_NaN();
  VisionPose zero_q = nan_q;
  zero_q.q_world_camera.coeffs().setZero();
  VisionPose nan_p;
  nan_p.capture_stamp_ns = 1'400'000'000;
  nan_p.p_world_camera_m.x() = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(f.update_vision(nan_q));
  EXPECT_FALSE(f.update_vision(zero_q));
  EXPECT_FALSE(f.update_vision(nan_p));
  EXPECT_EQ(f.vision_counters().bad_input, 3u);
  EXPECT_EQ(f.status(SelectiveEkfAid::kVisionAttitude).by_decision[static_cast<size_t>(
                Decision::kRejectedBadInput)],
            4u);
  EXPECT_TRUE(f.state().P.allFinite());
}

// ------------------------------------------------------------------ filter mechanics
TEST(SelectiveEkfCore, GivenManyUpdatesThenCovarianceStaysSymmetricPositiveDefinite) {
  RunOptions o;
  o.vision = tag(50.0);
  o.vision.dropout_fraction = 0.3;
  sim::SensorSimulator simu(handheld_with_magnet(Episode{}, 20.0));
  SelectiveEkf ekf(o.params);
  VisionSynthesizer synth(o.vision);
  while (!simu.done()) {
    const auto s = simu.next();
    synth.push_truth(s.imu.stamp_ns, s.truth.q_world_body, s.truth.p_world_m, true);
    ekf.update_imu(s.imu);
    for (const auto& v : synth.pop_arrived(s.imu.stamp_ns)) {
      ekf.update_vision(v);
    }
    const auto& p = ekf.state().P;
    ASSERT_EQ((p - p.transpose()).norm(), 0.0);
    // positive definite once predicted: the low-pass's error e starts known (zero: the low-pass
    // starts at the first sample, its frame at the body) and is given variance by the first step
    const double min_eig = Eigen::SelfAdjointEigenSolver<SelectiveEkf::Mat>(p).eigenvalues().minCoeff();
    if (ekf.state().pre.since_start_s > 0.0) {
      ASSERT_GT(min_eig, 0.0);
    } else {
      ASSERT_GE(min_eig, 0.0);
    }
  }
  EXPECT_GT(synth.frames_dropped(), 0u);
}

// A level device whose magnetometer says the heading is 30 deg off from where the filter starts
// (the device truly yawed, the gyro missed it), no vision to anchor the heading.
struct HeadingOffRun {
  bool quat_error_rejection_seen = false;
  bool any_distrust_seen = false;
  bool trusted_at_end = false;
  double final_error_deg = 0.0;
};
HeadingOffRun run_heading_off(SelectiveEkfParams p, int samples) {
  p.dip_deg = 60.0;
  SelectiveEkf f(p);
  int64_t t = 1'000'000'000;
  f.update_imu(level_sample(t));
  const Eigen::Quaterniond yaw = quat_from_euler_zyx(0.0, 0.0, 30.0 * kRadPerDeg);
  HeadingOffRun r;
  for (int k = 1; k <= samples; ++k) {
    t += 10'000'000;
    ImuSample s = level_sample(t);
    s.mag_ut = yaw.conjugate() * s.mag_ut;
    f.update_imu(s);
    r.quat_error_rejection_seen |= !f.mag_status().trusted && f.mag_status().quat_error_test_failed;
    r.any_distrust_seen |= !f.mag_status().trusted;
  }
  r.trusted_at_end = f.mag_status().trusted;
  r.final_error_deg = quat_angle_between(f.q_world_body(), yaw) * kDegPerRad;
  return r;
}

TEST(SelectiveEkfCore, GivenQuatErrorLockoutWhenNoVisionThenImuQuatAcceptedAgain) {
  // GIVEN the 30 deg heading offset with the paper's Gauss-Newton quaternion (kSplit applies the
  // quaternion-error test only while vision anchors the heading: see the next test)
  SelectiveEkfParams p;
  p.imu_measurement = ImuMeasurement::kQuaternion;
  const HeadingOffRun r = run_heading_off(p, 600);
  // THEN the quaternion-error test first distrusts q_imu, then the lock-out release lets the
  // undisturbed magnetometer pull the heading back
  EXPECT_TRUE(r.quat_error_rejection_seen);
  EXPECT_TRUE(r.trusted_at_end);
  EXPECT_LT(r.final_error_deg, 2.0);
}

TEST(SelectiveEkfCore, GivenUnseenTiltStepWhenDerivedTiltDensityThenTiltFollowsTheLowPassTimeConstant) {
  // GIVEN a static sensor at 200 Hz, converged for 30 s, then turned 5 deg about x without the gyro
  // seeing it (the accelerometer and magnetometer turn, the gyro reads 0)
  const double tau = SelectiveEkfParams{}.accel_lowpass_tau_s;  // the derived tilt time constant
  SelectiveEkf ekf{SelectiveEkfParams{}};
  const int64_t dt_ns = 5'000'000;
  const double step_deg = 5.0;
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(step_deg * kRadPerDeg, Eigen::Vector3d::UnitX()));
  std::vector<std::pair<double, double>> checks;  // (t after the step, s; tilt error, deg)
  for (int k = 0; k <= 30 * 200 + 4 * static_cast<int>(tau * 200); ++k) {
    ImuSample s = level_sample(int64_t{1'000'000'000} + k * dt_ns);
    const double t_after = (k - 30 * 200) * 0.005;
    if (t_after >= 0.0) {
      s.accel_mps2 = turn.conjugate() * s.accel_mps2;  // body-frame readings of the turned sensor
      s.mag_ut = turn.conjugate() * s.mag_ut;
    }
    ASSERT_TRUE(ekf.update_imu(s));
    for (double tc : {1.0, 2.0, 3.0}) {
      if (std::abs(t_after - tc * tau) < 1e-9) {
        const Eigen::Vector3d up_est = ekf.state().q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
        const Eigen::Vector3d up_true = s.accel_mps2.normalized();
        checks.emplace_back(t_after, angle_between_vectors(up_est, up_true) * kDegPerRad);
      }
    }
  }
  // THEN the tilt follows the accelerometer's low-pass no more slowly than a second lag of the same
  // time constant, e(t) <= e0 (1 + t / tau) exp(-t / tau) (two equal first-order lags in series).
  // (The old fixed density, a ~6 s tilt time constant, is 3.8 deg at t = tau: above the bound.)
  // It may get ahead of the uncorrected low-pass, e0 exp(-t / tau): a rotation the gyro did not
  // see is an error of the low-pass's frame too (the state e), which the tilt rows correct with
  // the attitude (3 tau: 0.08 deg against the lag's 0.25).
  constexpr double kTolDeg = 0.05;  // rounding of the discrete-time filter against the continuous lags
  ASSERT_EQ(checks.size(), 3u);
  for (const auto& [t, err] : checks) {
    const double two_lags = step_deg * (1.0 + t / tau) * std::exp(-t / tau);
    EXPECT_LE(err, two_lags + kTolDeg) << "t = " << t << " s";
  }
}

TEST(SelectiveEkfCore, GivenHeadingOffWithoutVisionWhenSplitThenMagnetometerTrustedAndPullsBack) {
  // GIVEN the same offset with the split measurements (default), 60 s (several time constants)
  const HeadingOffRun r = run_heading_off(SelectiveEkfParams{}, 6000);
  // THEN the undisturbed magnetometer (dip and |m| unchanged) is never distrusted for disagreeing
  // with a prediction nothing anchors, and the heading converges
  EXPECT_FALSE(r.any_distrust_seen);
  EXPECT_LT(r.final_error_deg, 2.0);
}

bool same_or_both_nan(double x, double y) { return x == y || (std::isnan(x) && std::isnan(y)); }

/// Every field of SelectiveEkfParams (Gauss-Newton and sample limits included), compared exactly.
void expect_same_params(const SelectiveEkfParams& a, const SelectiveEkfParams& b) {
  EXPECT_EQ(a.sigma_angular_accel, b.sigma_angular_accel);
  EXPECT_EQ(a.sigma_linear_accel, b.sigma_linear_accel);
  EXPECT_EQ(a.sigma_attitude_walk, b.sigma_attitude_walk);
  EXPECT_EQ(a.sigma_bias_walk, b.sigma_bias_walk);
  EXPECT_EQ(a.sigma_gyro_rps, b.sigma_gyro_rps);
  EXPECT_EQ(a.imu_measurement, b.imu_measurement);
  EXPECT_EQ(a.accel_lowpass_tau_s, b.accel_lowpass_tau_s);
  EXPECT_TRUE(same_or_both_nan(a.sigma_tilt_rad_sqrt_s, b.sigma_tilt_rad_sqrt_s));
  EXPECT_EQ(a.tilt_accel_ref_mps2, b.tilt_accel_ref_mps2);
  EXPECT_EQ(a.gravity_mps2, b.gravity_mps2);
  EXPECT_EQ(a.heading_dip_tolerance_deg, b.heading_dip_tolerance_deg);
  EXPECT_EQ(a.heading_norm_tolerance, b.heading_norm_tolerance);
  EXPECT_EQ(a.aiding_period_s, b.aiding_period_s);
  EXPECT_EQ(a.sigma_heading_rad_sqrt_s, b.sigma_heading_rad_sqrt_s);
  EXPECT_EQ(a.heading_disturbance_weight, b.heading_disturbance_weight);
  EXPECT_EQ(a.hard_iron, b.hard_iron);
  EXPECT_EQ(a.hard_iron_estimator.prior_sigma_ut, b.hard_iron_estimator.prior_sigma_ut);
  EXPECT_EQ(a.hard_iron_estimator.min_applied_ut, b.hard_iron_estimator.min_applied_ut);
  EXPECT_EQ(a.hard_iron_estimator.removed_log_lr, b.hard_iron_estimator.removed_log_lr);
  EXPECT_EQ(a.gyro_scale_error, b.gyro_scale_error);
  EXPECT_EQ(a.rest_detection, b.rest_detection);
  EXPECT_EQ(a.rest_gyro_max_rps, b.rest_gyro_max_rps);
  EXPECT_EQ(a.rest_accel_max_mps2, b.rest_accel_max_mps2);
  EXPECT_EQ(a.rest_min_s, b.rest_min_s);
  EXPECT_EQ(a.rest_filter_tau_s, b.rest_filter_tau_s);
  EXPECT_EQ(a.sigma_rest_rate_rps, b.sigma_rest_rate_rps);
  EXPECT_EQ(a.sigma_imu_quat_deg, b.sigma_imu_quat_deg);
  EXPECT_EQ(a.sigma_vision_deg, b.sigma_vision_deg);
  EXPECT_EQ(a.sigma_vision_m, b.sigma_vision_m);
  EXPECT_EQ(a.gating_enabled, b.gating_enabled);
  EXPECT_EQ(a.up_source, b.up_source);
  EXPECT_TRUE(same_or_both_nan(a.dip_deg, b.dip_deg)) << a.dip_deg << " vs " << b.dip_deg;
  EXPECT_EQ(a.startup_samples, b.startup_samples);
  EXPECT_EQ(a.disturbance_angle_threshold_deg, b.disturbance_angle_threshold_deg);
  EXPECT_EQ(a.mag_norm_test, b.mag_norm_test);
  EXPECT_EQ(a.mag_norm_threshold, b.mag_norm_threshold);
  EXPECT_EQ(a.quat_error_test, b.quat_error_test);
  EXPECT_EQ(a.quat_error_threshold_deg, b.quat_error_threshold_deg);
  EXPECT_EQ(a.action, b.action);
  EXPECT_EQ(a.inflate_factor, b.inflate_factor);
  EXPECT_EQ(a.untrusted_hold_s, b.untrusted_hold_s);
  EXPECT_EQ(a.q_error_lockout_s, b.q_error_lockout_s);
  EXPECT_EQ(a.vision_anchor_s, b.vision_anchor_s);
  EXPECT_EQ(a.vision_gate_sigma, b.vision_gate_sigma);
  EXPECT_EQ(a.vision_reset_after_rejections, b.vision_reset_after_rejections);
  EXPECT_EQ(a.history_s, b.history_s);
  EXPECT_EQ(a.vision_time_offset_s, b.vision_time_offset_s);
  EXPECT_TRUE(same_or_both_nan(a.imu_delay_s, b.imu_delay_s));
  EXPECT_EQ(a.output_max_correction_dps, b.output_max_correction_dps);
  EXPECT_EQ(a.q_body_camera.coeffs(), b.q_body_camera.coeffs());
  EXPECT_EQ(a.p_body_camera_m, b.p_body_camera_m);
  EXPECT_EQ(a.init_sigma_attitude_deg, b.init_sigma_attitude_deg);
  EXPECT_EQ(a.init_sigma_rate_rps, b.init_sigma_rate_rps);
  EXPECT_EQ(a.init_sigma_bias_rps, b.init_sigma_bias_rps);
  EXPECT_EQ(a.init_sigma_position_m, b.init_sigma_position_m);
  EXPECT_EQ(a.init_sigma_velocity_mps, b.init_sigma_velocity_mps);
  EXPECT_EQ(a.limits.min_accel_norm_mps2, b.limits.min_accel_norm_mps2);
  EXPECT_EQ(a.limits.min_mag_norm_ut, b.limits.min_mag_norm_ut);
  EXPECT_EQ(a.limits.max_dt_s, b.limits.max_dt_s);
  EXPECT_EQ(a.limits.max_gyro_rps, b.limits.max_gyro_rps);
  EXPECT_EQ(a.limits.max_accel_mps2, b.limits.max_accel_mps2);
  EXPECT_EQ(a.limits.max_mag_ut, b.limits.max_mag_ut);
  EXPECT_EQ(a.gauss_newton.max_iterations, b.gauss_newton.max_iterations);
  EXPECT_EQ(a.gauss_newton.tolerance_rad, b.gauss_newton.tolerance_rad);
  EXPECT_EQ(a.gauss_newton.mag_weight, b.gauss_newton.mag_weight);
  EXPECT_EQ(a.gauss_newton.startup_samples, b.gauss_newton.startup_samples);
  EXPECT_TRUE(same_or_both_nan(a.gauss_newton.dip_deg, b.gauss_newton.dip_deg));
}

// Defaults in one place: each shipped selective_ekf*.yaml holds only what differs from the C++
// defaults, so loading it gives exactly SelectiveEkfParams{} with those keys, every field compared
// (a rounded copy of a default, e.g. 0.0349066 for 2 deg/s, fails here).
TEST(SelectiveEkfConfig, GivenEachShippedYamlWhenLoadedThenItIsTheDefaultsWithOnlyItsDifferences) {
  const std::string dir = std::string(POISE_SOURCE_DIR) + "/config/filters/";
  const SelectiveEkfParams defaults;
  SelectiveEkfParams nogating;
  nogating.gating_enabled = false;
  const SelectiveEkfParams broad = broad_sensor_params();  // defaults + BROAD's IMU delay
  SelectiveEkfParams broad_nogating = broad;
  broad_nogating.gating_enabled = false;
  const std::pair<const char*, const SelectiveEkfParams*> files[] = {
      {"selective_ekf.yaml", &defaults},
      {"selective_ekf_nogating.yaml", &nogating},
      {"selective_ekf_broad.yaml", &broad},
      {"selective_ekf_broad_nogating.yaml", &broad_nogating},
  };
  for (const auto& [file, expected] : files) {
    SCOPED_TRACE(file);
    expect_same_params(load_selective_ekf_params(dir + file), *expected);
  }
}

TEST(SelectiveEkfConfig, GivenShippedYamlFilesWhenLoadedThenValidAndDistinct) {
  const std::string dir = std::string(POISE_SOURCE_DIR) + "/config/filters/";
  const SelectiveEkfParams on = load_selective_ekf_params(dir + "selective_ekf.yaml");
  const SelectiveEkfParams off = load_selective_ekf_params(dir + "selective_ekf_nogating.yaml");
  EXPECT_TRUE(on.gating_enabled);
  EXPECT_FALSE(off.gating_enabled);
  const SelectiveEkfParams defaults;
  EXPECT_EQ(on.disturbance_angle_threshold_deg, defaults.disturbance_angle_threshold_deg);
  EXPECT_EQ(on.quat_error_threshold_deg, defaults.quat_error_threshold_deg);
  EXPECT_TRUE(std::isnan(on.imu_delay_s));  // not known (the defaults'), like the parallel KF's
  EXPECT_TRUE(std::isnan(defaults.imu_delay_s));
  // BROAD's files: the same filter with the IMU delay measured by `poise calibrate imu-delay`
  const SelectiveEkfParams broad = load_selective_ekf_params(dir + "selective_ekf_broad.yaml");
  const SelectiveEkfParams broad_off = load_selective_ekf_params(dir + "selective_ekf_broad_nogating.yaml");
  EXPECT_GT(broad.imu_delay_s, 0.0);
  EXPECT_EQ(broad.imu_delay_s, broad_off.imu_delay_s);
  EXPECT_EQ(broad.imu_delay_s, kBroadImuDelayS);  // what `poise eval broad` uses without --config
  EXPECT_EQ(broad_sensor_params().imu_delay_s, kBroadImuDelayS);
  EXPECT_TRUE(broad.gating_enabled);
  EXPECT_FALSE(broad_off.gating_enabled);
  EXPECT_EQ(broad.sigma_imu_quat_deg, on.sigma_imu_quat_deg);
}

TEST(SelectiveEkfConfig, GivenTheFilterTableThenOnlyBroadEvaluationsGetTheBroadImuDelay) {
  CLI::App app{"poise"};
  cli::register_selective_ekf_cli(app);
  auto delay_of = [](const std::unique_ptr<AttitudeFilter>& f) {
    const auto* s = dynamic_cast<const SelectiveEkfFilter*>(f.get());
    return s == nullptr ? -1.0 : s->core().params().imu_delay_s;
  };
  // `poise eval broad` / `poise bench filters` without --config: BROAD's sensor
  EXPECT_EQ(delay_of(eval::make_filter_for_broad("selective")), kBroadImuDelayS);
  EXPECT_EQ(delay_of(eval::make_filter_for_broad("selective_vision30")), kBroadImuDelayS);
  // anything else (`poise process`) and an explicit config: no BROAD assumption
  EXPECT_TRUE(std::isnan(delay_of(eval::make_filter("selective"))));  // not known
  const std::string file = std::string(POISE_SOURCE_DIR) + "/config/filters/selective_ekf.yaml";
  EXPECT_TRUE(std::isnan(delay_of(eval::make_filter_for_broad("selective", file))));
}

TEST(SelectiveEkfConfig, GivenBadYamlWhenLoadedThenErrorNamesTheKey) {
  const std::string path = ::testing::TempDir() + "/sekf_bad.yaml";
  auto expect_error = [&path](const std::string& body, const std::string& needle) {
    std::ofstream(path) << body;
    try {
      (void)load_selective_ekf_params(path);
      ADD_FAILURE() << "no error for: " << body;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error("selective_ekf:\n  sigma_gyro_rsp: 0.1\n", "sigma_gyro_rsp");
  expect_error("selective_ekf:\n  sigma_gyro_rps: -1\n", "sigma_gyro_rps");
  expect_error("selective_ekf:\n  up_source: sideways\n", "up_source");
  expect_error("selective_ekf:\n  q_body_camera: [2, 0, 0, 0]\n", "q_body_camera");
  expect_error("selective_ekf:\n  gauss_newton:\n    max_iterations: 0\n", "max_iterations");
  expect_error("other: 1\n", "selective_ekf");
}

}  // namespace
}  // namespace poise

// ------------------------------------------------------------------ BROAD replay (real IMU data)
namespace poise {
namespace {

constexpr double kBroadGatedMaxDeg = 1.0;   // trial 32 gated total RMSE (measured 0.58 deg)
// Gating gains at least this much. With the split measurements the magnet can only pull the
// heading, weakly next to vision (the paper's Gauss-Newton quaternion also pulled the tilt:
// 71.7 deg ungated then; now 0.77 deg ungated vs 0.58 gated).
constexpr double kBroadGatingGainMinDeg = 0.1;

TEST(SelectiveEkfBroad, GivenAttachedMagnetTrialWhenGatedThenBeatsUngatedWithHybridVision) {
  POISE_REQUIRE_SHARED_DIR(shared);
  // GIVEN BROAD trial 32 (magnet attached at 1 cm) and the hybrid benchmark's vision
  const eval::BroadTrial trial =
      eval::load_broad(shared + "/broad/32_disturbed_attached_magnet_1cm.hdf5");
  SelectiveEkfParams ungated;
  ungated.gating_enabled = false;
  ungated.hard_iron = false;  // nothing removes the magnet's offset either
  // WHEN the selective EKF runs with and without gating
  SelectiveEvalFilter g(SelectiveEkfParams{}, hybrid_benchmark_vision());
  SelectiveEvalFilter u(ungated, hybrid_benchmark_vision());
  const eval::TrialErrors eg = eval::broad_errors(eval::run_filter(g, trial), trial);
  const eval::TrialErrors eu = eval::broad_errors(eval::run_filter(u, trial), trial);
  std::printf("trial 32 total RMSE: gated %.3f deg, ungated %.3f deg\n", eg.total_deg, eu.total_deg);
  // THEN the gated filter stays near the vision level and the ungated one follows the magnet
  EXPECT_LT(eg.total_deg, kBroadGatedMaxDeg);
  EXPECT_GT(eu.total_deg, eg.total_deg + kBroadGatingGainMinDeg);
  EXPECT_GT(g.core().mag_status().untrusted_samples, 0u);
  EXPECT_GT(g.core().vision_counters().replayed_imu_samples, 0u);
}

TEST(SelectiveEkfBroad, GivenTheMeasuredImuDelayWhenConfiguredThenCloserToTheReference) {
  POISE_REQUIRE_SHARED_DIR(shared);
  // GIVEN BROAD trial 30 (stationary magnet) with the hybrid benchmark's vision, and the IMU
  // delay measured on an undisturbed trial (01) only
  const eval::BroadTrial calib = eval::load_broad(shared + "/broad/01_undisturbed_slow_rotation_A.hdf5");
  eval::ImuDelayOptions o;
  o.rate_hz = calib.rate_hz;
  const eval::ImuDelayEstimate delay = eval::estimate_imu_delay(calib.gyr_rps, calib.opt_quat_wxyz, calib.movement, o);
  ASSERT_TRUE(delay.ok) << delay.why;
  const eval::BroadTrial trial = eval::load_broad(shared + "/broad/30_disturbed_stationary_magnet_C.hdf5");
  SelectiveEkfParams with_delay;
  with_delay.imu_delay_s = delay.delay_s;
  // WHEN the filter runs without and with that delay
  SelectiveEvalFilter a(SelectiveEkfParams{}, hybrid_benchmark_vision());
  SelectiveEvalFilter b(with_delay, hybrid_benchmark_vision());
  const eval::TrialErrors ea = eval::broad_errors(eval::run_filter(a, trial), trial);
  const eval::TrialErrors eb = eval::broad_errors(eval::run_filter(b, trial), trial);
  std::printf("IMU delay from trial 01: %.3f ms; trial 30 total RMSE %.3f deg without, %.3f deg with\n",
              delay.delay_s * 1e3, ea.total_deg, eb.total_deg);
  // THEN the delay is a few ms (BROAD's IMU lags its reference) and compensating it helps clearly
  EXPECT_GT(delay.delay_s, kBroadImuDelayMinS);
  EXPECT_LT(delay.delay_s, kBroadImuDelayMaxS);
  EXPECT_LT(eb.total_deg, ea.total_deg - kBroadDelayGainDeg);
}

// ------------------------------------------------------------------ IMU only (issue 21)
// Tolerances with their reasons (deg unless stated).
constexpr double kExtAccelTiltMaxDeg = 3.0;   // tilt under 12 m/s^2 external accelerations: the
                                               // low-passed gravity direction, not the raw accel
constexpr double kMagnetTiltMaxDeg = 0.5;     // tilt of a static device while a magnet is near:
                                               // the magnetometer has no tilt row in kSplit
constexpr double kBiasErrorMaxDps = 0.1;      // bias estimate vs the simulator's 0.44 deg/s bias
constexpr double kBlackoutMaxDeg = 3.0;       // error during a 20 s vision blackout (IMU only)
constexpr double kOutputStepBiasDeg = 0.01;  // output step beyond limit x dt: the output also
                                             // turns with gyro - bias (bias < 1 deg/s x 10 ms)
constexpr double kOutputSettleMarginS = 0.2;     // heading/tilt rows keep the state moving a bit
constexpr double kReturnStepMarginDeg = 1.0;  // output step at vision return beyond the error
                                               // accumulated during the blackout: one vision
                                               // noise sigma (the first frame's own error)

double inclination_deg(const Eigen::Quaterniond& est, const Eigen::Quaterniond& truth) {
  return heading_inclination_of_world_error(est * truth.conjugate()).inclination_rad * kDegPerRad;
}

TEST(SelectiveEkfImuOnly, GivenLargeExternalAccelerationsWhenSplitThenTiltStaysNearTruth) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  // GIVEN the simulator's fast_motion scenario (up to 12 m/s^2 per axis, 230 deg/s), no magnet,
  // no vision: the accelerometer is far from gravity most of the time
  const sim::SimConfig cfg = sim::make_scenario("fast_motion", kRateHz, kSeed);
  auto run_tilt = [&cfg](ImuMeasurement m) {
    sim::SensorSimulator simu(cfg);
    SelectiveEkfParams p;
    p.imu_measurement = m;
    SelectiveEkf ekf(p);
    double worst = 0.0;
    while (!simu.done()) {
      const auto s = simu.next();
      ekf.update_imu(s.imu);
      if (s.truth.t_s > 2.0) {
        worst = std::max(worst, inclination_deg(ekf.q_world_body(), s.truth.q_world_body));
      }
    }
    return worst;
  };
  // WHEN the filter runs with the split tilt/heading measurements and with the paper's quaternion
  const double split = run_tilt(ImuMeasurement::kSplit);
  const double paper = run_tilt(ImuMeasurement::kQuaternion);
  std::printf("fast_motion max tilt error: split %.2f deg, Gauss-Newton quaternion %.2f deg\n", split,
              paper);
  // THEN the tilt stays near the truth and clearly better than with the raw-accelerometer quaternion
  EXPECT_LT(split, kExtAccelTiltMaxDeg);
  EXPECT_GT(paper, split);
}

TEST(SelectiveEkfImuOnly, GivenMagnetNearStaticDeviceWhenSplitThenTiltUnaffected) {
  // GIVEN the static_magnet scenario (a 35 uT magnet 15-36 s), no vision
  sim::SimConfig cfg = sim::make_scenario("static_magnet", kRateHz, kSeed);
  cfg.duration_s = 45.0;
  sim::SensorSimulator simu(cfg);
  SelectiveEkf ekf;
  double worst_tilt = 0.0;
  int flagged = 0;
  int n = 0;
  while (!simu.done()) {
    const auto s = simu.next();
    ekf.update_imu(s.imu);
    if (s.truth.t_s >= 15.0 && s.truth.t_s < 36.0) {
      worst_tilt = std::max(worst_tilt, inclination_deg(ekf.q_world_body(), s.truth.q_world_body));
      flagged += ekf.mag_status().trusted ? 0 : 1;
      ++n;
    }
  }
  std::printf("static magnet: max tilt error %.3f deg, magnetometer untrusted %.3f of the episode\n",
              worst_tilt, static_cast<double>(flagged) / n);
  // THEN the tilt does not move (the magnetometer only measures heading) and the magnet is flagged
  EXPECT_LT(worst_tilt, kMagnetTiltMaxDeg);
  EXPECT_GT(static_cast<double>(flagged) / n, 0.5);
}

TEST(SelectiveEkfImuOnly, GivenGyroBiasWhenRestsAndMotionThenBiasEstimated) {
  // GIVEN the random_motion scenario (gyro bias (0.3, -0.2, 0.25) deg/s, rests between motion)
  const sim::SimConfig cfg = sim::make_scenario("random_motion", kRateHz, kSeed);
  sim::SensorSimulator simu(cfg);
  SelectiveEkf ekf;
  while (!simu.done()) {
    ekf.update_imu(simu.next().imu);
  }
  // THEN the bias state holds the simulator's bias
  const Eigen::Vector3d err = ekf.state().b_rps - cfg.noise.gyro_bias_rps;
  std::printf("bias estimate (%.3f, %.3f, %.3f) deg/s, truth (%.3f, %.3f, %.3f), error %.3f deg/s\n",
              ekf.state().b_rps.x() * kDegPerRad, ekf.state().b_rps.y() * kDegPerRad,
              ekf.state().b_rps.z() * kDegPerRad, cfg.noise.gyro_bias_rps.x() * kDegPerRad,
              cfg.noise.gyro_bias_rps.y() * kDegPerRad, cfg.noise.gyro_bias_rps.z() * kDegPerRad,
              err.norm() * kDegPerRad);
  EXPECT_LT(err.norm() * kDegPerRad, kBiasErrorMaxDps);
  EXPECT_GT(ekf.status(SelectiveEkfAid::kZeroRate).fused, 0u);
}

TEST(SelectiveEkfImuOnly, GivenVisionBlackoutWhenVisionReturnsThenNoStepBeyondTheDrift) {
  SCOPED_TRACE(::testing::Message() << "seed " << kSeed);
  // GIVEN a handheld device (no magnet) with the tag visible, then hidden for 20 s (10-30 s)
  Episode none;
  none.start_s = 100.0;
  RunOptions o;
  o.vision = tag(50.0);
  o.hide_from_s = 10.0;
  o.hide_to_s = 30.0;
  // WHEN the filter runs through the blackout and the return
  const auto steps = run(handheld_with_magnet(none, 40.0), o);
  // THEN the IMU alone keeps the attitude during the blackout...
  const Window dark = window(steps, o.hide_from_s, o.hide_to_s);
  EXPECT_LT(dark.max_err, kBlackoutMaxDeg);
  // ... and the output step when vision returns (rotation not explained by the truth's own
  // motion between samples) is no larger than the error accumulated in the dark plus the noise
  // of a frame
  double err_at_return = 0.0;
  double max_step = 0.0;
  sim::SensorSimulator truth_sim(handheld_with_magnet(none, 40.0));
  std::vector<Eigen::Quaterniond> truth;
  while (!truth_sim.done()) {
    truth.push_back(truth_sim.next().truth.q_world_body);
  }
  ASSERT_EQ(truth.size(), steps.size());
  for (size_t i = 1; i < steps.size(); ++i) {
    if (steps[i].t_s < o.hide_to_s) {
      err_at_return = steps[i].err_deg;
    } else if (steps[i].t_s < o.hide_to_s + 1.0) {
      const Eigen::Quaterniond moved = truth[i - 1].conjugate() * truth[i];  // body-frame motion
      max_step = std::max(max_step,
                          quat_angle_between(steps[i].q, steps[i - 1].q * moved) * kDegPerRad);
    }
  }
  std::printf("blackout: max error %.2f deg, error at return %.2f deg, largest step %.3f deg\n",
              dark.max_err, err_at_return, max_step);
  EXPECT_LT(max_step, err_at_return + kReturnStepMarginDeg);
  const Window back = window(steps, o.hide_to_s + 2.0, 40.0);
  EXPECT_LT(back.max_err, kFollowVisionMaxDeg);
}

TEST(SelectiveEkfVision, GivenAVisionResetWhenOutputLimitedThenTheOutputGlidesAtTheLimit) {
  // GIVEN a level device at rest, 100 Hz, the tag seen at identity, then at 20 deg yaw (the
  // camera re-localised: the gate rejects it 10 times, then the state resets to it)
  SelectiveEkfParams p;
  p.imu_delay_s = 0.0;  // the samples describe the stamp: a frame at a sample's stamp is on time
  SelectiveEkf f(p);  // output_max_correction_dps = 20 by default
  const double limit_dps = f.params().output_max_correction_dps;
  const Eigen::Quaterniond yaw20 = quat_from_euler_zyx(0.0, 0.0, 20.0 * kRadPerDeg);
  Eigen::Quaterniond prev = Eigen::Quaterniond::Identity();
  double max_step_deg = 0.0;
  double state_jump_deg = 0.0;
  double settled_at_s = -1.0;
  int reset_k = -1;
  for (int k = 0; k < 400; ++k) {
    const int64_t t = int64_t{1'000'000'000} + k * int64_t{10'000'000};
    f.update_imu(level_sample(t));
    const Eigen::Quaterniond before = f.state_output();
    if (k % 3 == 0) {
      VisionPose v;
      v.capture_stamp_ns = t;
      v.q_world_camera = k < 150 ? Eigen::Quaterniond::Identity() : yaw20;
      f.update_vision(v);
    }
    const double jump = quat_angle_between(before, f.state_output()) * kDegPerRad;
    state_jump_deg = std::max(state_jump_deg, jump);
    if (reset_k < 0 && jump > 10.0) {
      reset_k = k;
    }
    if (k > 150) {
      max_step_deg = std::max(max_step_deg, quat_angle_between(prev, f.q_world_body()) * kDegPerRad);
    }
    if (reset_k >= 0 && settled_at_s < 0.0 &&
        quat_angle_between(f.q_world_body(), f.state_output()) * kDegPerRad < 0.01) {
      settled_at_s = (k - reset_k) * 0.01;
    }
    prev = f.q_world_body();
  }
  // THEN the state jumps by degrees, the output moves at most limit x dt per sample (no gyro
  // motion here) and catches up within the 20 deg / limit glide after the reset
  std::printf("state jump %.2f deg, largest output step %.3f deg, settled %.2f s after it\n",
              state_jump_deg, max_step_deg, settled_at_s);
  EXPECT_GT(state_jump_deg, 10.0);
  EXPECT_LE(max_step_deg, limit_dps * 0.01 + kOutputStepBiasDeg);
  EXPECT_GT(settled_at_s, 0.0);
  EXPECT_LT(settled_at_s, 20.0 / limit_dps + kOutputSettleMarginS);
}

TEST(SelectiveEkfVision, GivenBlackoutOptionsWhenSynthesisedThenNoFrameInsideTheBlackouts) {
  // GIVEN 30 Hz vision with 3 s blackouts every 10 s, no random dropouts
  VisionSynthParams v = tag(0.0);
  v.blackout_s = 3.0;
  v.blackout_every_s = 10.0;
  VisionSynthesizer synth(v);
  int inside = 0;
  int outside = 0;
  for (int k = 0; k < 3000; ++k) {  // 30 s at 100 Hz
    const int64_t t = int64_t{10'000'000} * k;
    synth.push_truth(t, Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero(), true);
    for (const VisionPose& f : synth.pop_arrived(t)) {
      const double phase = std::fmod(static_cast<double>(f.capture_stamp_ns) * 1e-9, 10.0);
      (phase >= 7.0 ? inside : outside) += 1;
    }
  }
  // THEN every frame falls outside [7, 10) s of each 10 s, and the rest is delivered (30 Hz x 21 s)
  EXPECT_EQ(inside, 0);
  EXPECT_NEAR(outside, 30 * 21, 3);
  // AND inconsistent options are refused
  v.blackout_every_s = 2.0;
  EXPECT_THROW(VisionSynthesizer{v}, std::invalid_argument);
}

TEST(SelectiveEkfCore, GivenAFullStateTakenMidRunWhenRestoredIntoAnotherFilterThenBothGiveIdenticalOutputs) {
  // GIVEN a filter 20 s into the static_magnet scenario with a 30 Hz tag 50 ms late (vision
  // waiting in the history, magnet near from 15 s)
  sim::SensorSimulator simu(sim::make_scenario("static_magnet", 100.0, 3));
  VisionSynthesizer synth(tag(50.0));
  SelectiveEkf a;
  SelectiveEkf b;
  const auto step = [&](bool both) {
    const sim::SimSample s = simu.next();
    synth.push_truth(s.imu.stamp_ns, s.truth.q_world_body, s.truth.p_world_m, true);
    const bool a_ok = a.update_imu(s.imu);
    ASSERT_EQ(a_ok, both ? b.update_imu(s.imu) : a_ok);
    for (const VisionPose& v : synth.pop_arrived(s.imu.stamp_ns)) {
      a.update_vision(v);
      if (both) {
        b.update_vision(v);
      }
    }
  };
  for (int k = 0; k < 2000; ++k) {
    step(false);
  }
  ASSERT_GT(a.vision_counters().applied, 0u);
  // WHEN its full state is copied into a new filter with the same parameters
  b.set_full_state(a.full_state());
  // THEN both give bit-identical outputs on the next 20 s (full_state() holds everything)
  for (int k = 0; k < 2000; ++k) {
    step(true);
    ASSERT_EQ(a.q_world_body().coeffs(), b.q_world_body().coeffs()) << k;
    ASSERT_EQ(a.state().P, b.state().P) << k;
    ASSERT_EQ(a.mag_status().trusted, b.mag_status().trusted) << k;
  }
  EXPECT_EQ(a.vision_counters().applied, b.vision_counters().applied);
  // AND reset() gives back a new filter's state
  a.reset();
  const SelectiveEkf fresh;
  EXPECT_EQ(a.initialized(), fresh.initialized());
  EXPECT_EQ(a.state().P, fresh.state().P);
  EXPECT_EQ(a.vision_counters().applied, 0u);
}

// One validation shape (ParamCheck): a bad value of a key is an error at construction that names
// the key as in the YAML file and its range/unit, never a silent repair or a NaN later.
TEST(SelectiveEkfParams, GivenABadValueOfAKeyWhenTheFilterIsBuiltThenTheErrorNamesTheKey) {
  testing::expect_bad_values_name_their_keys<SelectiveEkfParams>("selective_ekf", SelectiveEkfParams{}, {
    {"sigma_gyro_rps", [](SelectiveEkfParams& p) { p.sigma_gyro_rps = 0.0; }},
    {"heading_dip_tolerance_deg", [](SelectiveEkfParams& p) { p.heading_dip_tolerance_deg = std::nan(""); }},
    {"imu_delay_s", [](SelectiveEkfParams& p) { p.imu_delay_s = 0.1; }},
    {"gyro_scale_error", [](SelectiveEkfParams& p) { p.gyro_scale_error = -0.01; }},
    {"limits.max_dt_s", [](SelectiveEkfParams& p) { p.limits.max_dt_s = 0.0; }},
    {"gyro_noise_density_rps_per_sqrt_hz", [](SelectiveEkfParams& p) { p.gyro_noise_density_rps_per_sqrt_hz = 0.0; }},
    {"accel_noise_density_mps2_per_sqrt_hz",
     [](SelectiveEkfParams& p) { p.accel_noise_density_mps2_per_sqrt_hz = std::numeric_limits<double>::infinity(); }},
    {"gyro_bias_walk_rps_per_sqrt_s", [](SelectiveEkfParams& p) { p.gyro_bias_walk_rps_per_sqrt_s = -1e-6; }}
  }, [](const SelectiveEkfParams& p) { SelectiveEkf f(p); });
}

// The figures of the sensor (gyro and accelerometer noise densities, gyro bias walk): null (or
// absent) = not known, a number in range is taken, anything else is refused naming the key. Only
// the estimate's error covariance reads them: the estimate is the same bit for bit whatever their
// values (oracle: the default filter's), and the published covariance differs.
TEST(SelectiveEkfParams, GivenTheSensorFiguresInAFileWhenLoadedThenNullIsNotKnownAHostileValueIsRefusedAndTheEstimateIgnoresThem) {
  const std::string path = ::testing::TempDir() + "/sel_sensor_figures.yaml";
  auto load = [&](const std::string& text) {
    std::FILE* f = std::fopen(path.c_str(), "w");
    EXPECT_NE(f, nullptr);
    std::fputs(text.c_str(), f);
    std::fclose(f);
    return load_selective_ekf_params(path);
  };
  const SelectiveEkfParams defaults;
  EXPECT_TRUE(std::isnan(defaults.gyro_noise_density_rps_per_sqrt_hz));
  EXPECT_TRUE(std::isnan(defaults.accel_noise_density_mps2_per_sqrt_hz));
  EXPECT_TRUE(std::isnan(defaults.gyro_bias_walk_rps_per_sqrt_s));
  using Field = double SelectiveEkfParams::*;
  const std::pair<const char*, Field> figures[] = {
      {"gyro_noise_density_rps_per_sqrt_hz", &SelectiveEkfParams::gyro_noise_density_rps_per_sqrt_hz},
      {"accel_noise_density_mps2_per_sqrt_hz", &SelectiveEkfParams::accel_noise_density_mps2_per_sqrt_hz},
      {"gyro_bias_walk_rps_per_sqrt_s", &SelectiveEkfParams::gyro_bias_walk_rps_per_sqrt_s}};
  for (const auto& [key, field] : figures) {
    SCOPED_TRACE(key);
    const std::string head = std::string("selective_ekf:\n  ") + key + ": ";
    EXPECT_TRUE(std::isnan(load(head + "~\n").*field));
    const SelectiveEkfParams given = load(head + "1.0e-4\n");
    for (const auto& [other, other_field] : figures) {
      if (other_field == field) {
        EXPECT_EQ(given.*field, 1.0e-4);
      } else {
        EXPECT_TRUE(std::isnan(given.*other_field)) << other;
      }
    }
    for (const char* bad : {"-1e-6", "1e308", ".inf", "fast", "[1, 2]"}) {
      const std::string msg = testing::error_message([&] { load(head + bad + "\n"); });
      EXPECT_NE(msg.find(key), std::string::npos) << bad << " -> '" << msg << "'";
    }
  }
  // the estimate is the same bit for bit whatever the figures; the published covariance is not
  SelectiveEkfParams told;
  told.gyro_noise_density_rps_per_sqrt_hz = 6.17e-5;
  told.accel_noise_density_mps2_per_sqrt_hz = 2.83e-3;
  told.gyro_bias_walk_rps_per_sqrt_s = 0.0;
  SelectiveEkf unknown(defaults);
  SelectiveEkf known(told);
  sim::SensorSimulator a(sim::make_scenario("random_motion", kRateHz, kSeed));
  bool differs = false;
  while (!a.done()) {
    const sim::SimSample s = a.next();
    ASSERT_EQ(unknown.update_imu(s.imu), known.update_imu(s.imu));
    ASSERT_EQ(unknown.q_world_body().coeffs(), known.q_world_body().coeffs());
    ASSERT_EQ(unknown.state().P, known.state().P);
    differs = differs || unknown.attitude_covariance() != known.attitude_covariance();
  }
  EXPECT_TRUE(differs);
}

TEST(SelectiveEkfParams, GivenABadGaussNewtonValueThenTheErrorNamesTheNestedKey) {
  SelectiveEkfParams p;
  p.gauss_newton.max_iterations = 0;
  const std::string msg = testing::invalid_argument_message([&] { SelectiveEkf f(p); });
  EXPECT_NE(msg.find("selective_ekf.gauss_newton parameter max_iterations must be"), std::string::npos) << msg;
}

}  // namespace
}  // namespace poise

namespace poise {

// The test accessor SelectiveEkfFullState befriends: spoils the state of a copy (the only way
// there: no input that passes the checks gets the filter into it).
struct SelectiveEkfTestAccess {
  static SelectiveEkfState& state(SelectiveEkfFullState& f) { return f.x_; }
};

namespace {

// State health (issue 19): a non-finite state or a covariance with a NaN, a negative variance or
// that is not positive semi-definite resets the filter on the next update, counted, nothing
// non-finite comes out, and it re-converges. Oracle: the simulator's truth.
TEST(SelectiveEkfCore, GivenAnUnhealthyStateWhenUpdatedThenTheFilterResetsCountsItAndReconverges) {
  constexpr double kReconvergedDeg = 1.0;  // total attitude error 20 s after the reset, deg
  constexpr int kSpoilAt = 1000;           // 10 s at 100 Hz
  using K = SelectiveEkf;
  struct Case {
    const char* name;
    void (*spoil)(SelectiveEkfState&);
  };
  const Case cases[] = {
      {"NaN attitude", [](SelectiveEkfState& x) { x.q_world_body.coeffs().setConstant(std::nan("")); }},
      {"NaN covariance entry", [](SelectiveEkfState& x) { x.P(K::kB, K::kTh) = std::nan(""); }},
      {"negative variance", [](SelectiveEkfState& x) { x.P(K::kTh, K::kTh) = -1e-4; }},
      {"indefinite covariance",  // positive diagonal: found by the periodic LDLT check
       [](SelectiveEkfState& x) {
         const double v = x.P(K::kTh, K::kTh);
         x.P(K::kTh, K::kTh + 1) = x.P(K::kTh + 1, K::kTh) = 10.0 * std::max(v, 1e-6);
       }},
  };
  for (const Case& c : cases) {
    sim::SimConfig cfg = sim::make_scenario("static_magnet", kRateHz, kSeed);
    cfg.magnets.clear();
    cfg.duration_s = 30.0;
    sim::SensorSimulator sim(cfg);
    SelectiveEkf ekf;
    sim::SimSample s;
    for (int k = 0; !sim.done(); ++k) {
      s = sim.next();
      if (k == kSpoilAt) {
        SelectiveEkfFullState full = ekf.full_state();
        c.spoil(SelectiveEkfTestAccess::state(full));
        ekf.set_full_state(full);
      }
      const uint64_t resets_before = ekf.state_resets();
      const bool used = ekf.update_imu(s.imu);
      ASSERT_TRUE(ekf.q_world_body().coeffs().allFinite()) << c.name << " at " << k;
      ASSERT_TRUE(ekf.state().P.allFinite()) << c.name << " at " << k;
      if (ekf.state_resets() != resets_before) {  // the resetting update: refused, not initialised
        EXPECT_FALSE(used) << c.name;
        EXPECT_FALSE(ekf.initialized()) << c.name;
        EXPECT_STREQ(selective_ekf_sources(ekf)[0].reason, kStateResetReason) << c.name;
      }
      if (k == kSpoilAt + static_cast<int>(StateHealth::kFullCheckEvery)) {
        EXPECT_EQ(ekf.state_resets(), 1u) << c.name;  // within one full-check period
      }
    }
    EXPECT_EQ(ekf.state_resets(), 1u) << c.name;
    EXPECT_EQ(ekf.imu_rejections().total(), 0u) << c.name;
    const double err_deg = quat_angle_between(ekf.q_world_body(), s.truth.q_world_body) * kDegPerRad;
    std::printf("%s: error %.3f deg 20 s after the reset\n", c.name, err_deg);
    EXPECT_LT(err_deg, kReconvergedDeg) << c.name;
  }
}


// ------------------------------------------------------------------ the tilt rows and the bias
// A level sensor at rest with a gyro bias the filter does not know (its prior, 0.01 rad/s, covers
// it), rest detection off so that only the tilt rows can teach the bias. The low-passed up vector
// lags the frame the bias turns: read as tilt alone, that lag made the tilt confident and wrong.
// With the bias columns the tilt error stays inside what the published covariance admits.
// Oracle: the true attitude (level, heading north) and the chi-square bound for 2 degrees of
// freedom at 99.7 % (11.6) on the tilt block.
TEST(SelectiveEkfTiltBias, GivenAnUnknownGyroBiasAtRestWhenOnlyTheTiltTeachesItThenTheTiltErrorStaysInsideItsCovariance) {
  constexpr double kRateHz = 100.0;
  constexpr double kRunS = 30.0;
  constexpr double kTilt2Dof997 = 11.62;  // chi-square quantile, 2 dof, 99.7 %
  constexpr double kBiasTolDps = 0.1;     // deg/s: learnt by the end
  const Eigen::Vector3d bias = Eigen::Vector3d(0.4, -0.3, 0.0) * kRadPerDeg;
  SelectiveEkfParams p;
  p.rest_detection = false;
  // the sensor described as it is: a quiet gyro (the simulator's 0.05 deg/s), no model error
  p.sigma_gyro_rps = 0.05 * kRadPerDeg;
  p.sigma_attitude_walk = 0.0;
  p.gyro_scale_error = 0.0;
  SelectiveEkf ekf(p);
  const int n = static_cast<int>(kRunS * kRateHz);
  int outside = 0;
  double worst = 0.0;
  for (int k = 0; k <= n; ++k) {
    ImuSample s = level_sample(int64_t{1'000'000'000} + k * int64_t{10'000'000});
    s.gyro_rps = bias;
    ASSERT_TRUE(ekf.update_imu(s));
    const Eigen::Vector3d e = world_attitude_error(ekf.q_world_body(), Eigen::Quaterniond::Identity());
    const Eigen::Matrix2d c = ekf.attitude_covariance().topLeftCorner<2, 2>();
    const double nees = e.head<2>().dot(c.inverse() * e.head<2>());
    worst = std::max(worst, nees);
    outside += nees > kTilt2Dof997 ? 1 : 0;
  }
  const Eigen::Vector3d b_err = (ekf.state().b_rps - bias) * kDegPerRad;
  std::printf("unknown bias at rest: tilt NEES at most %.2f, %d of %d samples above %.2f; bias error %.3f %.3f deg/s\n",
              worst, outside, n + 1, kTilt2Dof997, b_err.x(), b_err.y());
  EXPECT_EQ(outside, 0);
  EXPECT_LT(std::abs(b_err.x()), kBiasTolDps);
  EXPECT_LT(std::abs(b_err.y()), kBiasTolDps);
}


// The first estimate of a start at rest with the accelerometer's noise known: its tilt is one
// sample's, whose noise has no figure before an interval is known (the prior is published in its
// place) and whose rest test lets an acceleration across gravity through (|a| - g within
// rest_accel_max_mps2).
struct FirstEstimate {
  Eigen::Vector3d error;   ///< world-frame error of the first published estimate, rad
  Eigen::Matrix3d cov;     ///< its published covariance, rad^2
};

FirstEstimate first_estimate(SelectiveEkf& ekf, const Eigen::Quaterniond& q_true,
                             const Eigen::Vector3d& ext_world_mps2, const Eigen::Vector3d& noise_mps2,
                             int64_t stamp_ns) {
  ImuSample s;
  s.stamp_ns = stamp_ns;
  s.accel_mps2 = q_true.conjugate() * (Eigen::Vector3d(0, 0, ekf.params().gravity_mps2) + ext_world_mps2) + noise_mps2;
  s.gyro_rps.setZero();
  EXPECT_TRUE(ekf.update_imu(s));
  return {world_attitude_error(ekf.q_world_body(), q_true), ekf.predict_horizon().covariance};
}

TEST(SelectiveEkfStart, GivenAStartAtRestWithTheAccelerometerNoiseKnownWhenTheFirstEstimateIsPublishedThenItsCovarianceIsPositiveDefiniteAndCoversTheTiltError) {
  constexpr double kRateHz = 200.0;
  constexpr double kTilt2Dof95 = 5.991;      // chi-square quantile, 2 dof, 95 %
  constexpr double kMinEigenRad2 = 1e-8;     // rad^2: a usable covariance, (0.006 deg)^2
  constexpr double kAcrossGravityMps2 = 3.0;  // |a| - g = 0.45 m/s^2: passes the rest test (0.5)
  constexpr int kSeeds = 50;
  SelectiveEkfParams p;
  p.accel_noise_density_mps2_per_sqrt_hz = 0.04 / std::sqrt(kRateHz);  // 0.04 m/s^2 per sample
  p.imu_delay_s = 0.0;
  const double sigma_mps2 = p.accel_noise_density_mps2_per_sqrt_hz * std::sqrt(kRateHz);
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> angle(-0.5, 0.5);  // rad: roll, pitch
  int outside = 0;
  double worst = 0.0;
  double min_eigen = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 2 * kSeeds; ++k) {
    // GIVEN a sensor at rest at a random tilt (ZYX yaw 0, no magnetometer: the start's yaw is 0),
    // its accelerometer noise known, every other sample also with an acceleration across gravity
    const Eigen::Quaterniond q_true = Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitY()) *
                                      Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitX());
    const double az = angle(rng) * 4.0 * kPi;
    const Eigen::Vector3d ext = (k % 2 == 1 ? kAcrossGravityMps2 : 0.0) * Eigen::Vector3d(std::cos(az), std::sin(az), 0.0);
    const Eigen::Vector3d noise = sigma_mps2 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
    SelectiveEkf ekf(p);
    // WHEN its first sample is taken, and again after a reset (a delay learnt: the node's restart)
    for (int start = 0; start < 2; ++start) {
      if (start == 1) {
        ekf.reset();
      }
      const FirstEstimate f = first_estimate(ekf, q_true, ext, noise, int64_t{1'000'000'000} * (start + 1));
      // THEN the covariance is positive definite and its tilt covers the tilt's error
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (f.cov + f.cov.transpose()));
      min_eigen = std::min(min_eigen, eig.eigenvalues().minCoeff());
      const Eigen::Matrix2d c = f.cov.topLeftCorner<2, 2>();
      const double nees = f.error.head<2>().dot(c.inverse() * f.error.head<2>());
      worst = std::max(worst, nees);
      outside += nees > kTilt2Dof95 ? 1 : 0;
    }
  }
  std::printf("first estimate: smallest eigenvalue %.3g rad^2, tilt NEES at most %.3f, %d of %d above %.3f\n",
              min_eigen, worst, outside, 4 * kSeeds, kTilt2Dof95);
  EXPECT_GT(min_eigen, kMinEigenRad2);
  EXPECT_EQ(outside, 0);
}

// Past the first sample: a start "at rest" whose first samples carry an acceleration across
// gravity that passes the one-sample rest test. Both the attitude and the accelerometer low-pass
// start on the tilted vector; the tilt error is atan(a / g) (the oracle, independent of the
// filter) and decays only as the low-pass forgets those samples (accel_lowpass_tau_s, 3 s). The
// published tilt covariance must cover it at every sample of the first seconds: the tilt NEES
// (2 degrees of freedom) at most its 95 % quantile. It claimed the accelerometer's noise
// (0.23 deg) from the second sample on, against an error of 17 deg.
struct StartAcrossGravity {
  int samples = 0;
  int outside = 0;     ///< samples whose tilt NEES is above the 95 % quantile
  int start_off = 0;   ///< cases whose first error is not atan(a / g)
  double worst = 0.0;  ///< largest tilt NEES
  double worst_t = 0.0;
};

constexpr double kStartRateHz = 200.0;
constexpr double kTilt2Dof95Start = 5.991;  // chi-square quantile, 2 dof, 95 %
// m/s^2: |a| - g = 0.45 m/s^2, near the rest test's 0.5; and one whose change, when it ends, is
// inside the rest test's tolerance (0.5 m/s^2), 1.75 deg
constexpr double kAcrossGravityMps2[2] = {3.0, 0.3};

/// 16 cases over kRunS (five low-pass time constants); with vision_period_s > 0, frames of the
/// true attitude (0.2 deg) every vision_period_s from 0.05 s, before the start is settled (0.5 s).
StartAcrossGravity run_starts_across_gravity(double vision_period_s) {
  constexpr double kRunS = 15.0;              // s
  constexpr double kStartOracleTolDeg = 1.0;  // the first estimate's error against atan(a / g)
  constexpr double kFirstFrameS = 0.05;       // s
  constexpr double kFrameSigmaRad = 0.2 * kRadPerDeg;
  constexpr int kCases = 16;
  SelectiveEkfParams told;  // the accelerometer's noise told (P_err: the low-pass's own noise) or not
  told.accel_noise_density_mps2_per_sqrt_hz = 0.04 / std::sqrt(kStartRateHz);  // 0.04 m/s^2 per sample
  told.imu_delay_s = 0.0;
  SelectiveEkfParams not_told = told;
  not_told.accel_noise_density_mps2_per_sqrt_hz = std::nan("");
  const double sigma_mps2 = told.accel_noise_density_mps2_per_sqrt_hz * std::sqrt(kStartRateHz);
  const double g = told.gravity_mps2;
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> unit(-0.5, 0.5);
  const auto dt_ns = static_cast<int64_t>(1e9 / kStartRateHz);
  const int n = static_cast<int>(kRunS * kStartRateHz);
  StartAcrossGravity r;
  r.samples = kCases * n;
  for (int c = 0; c < kCases; ++c) {
    // GIVEN a sensor at rest at a random tilt (yaw 0, no magnetometer), the acceleration across
    // gravity in a random direction over its first sample or (every other case) its first 0.1 s,
    // the accelerometer's noise told to the filter in half of the cases, of either size
    const Eigen::Quaterniond q_true = Eigen::AngleAxisd(unit(rng), Eigen::Vector3d::UnitY()) *
                                      Eigen::AngleAxisd(unit(rng), Eigen::Vector3d::UnitX());
    const double az = unit(rng) * 4.0 * kPi;
    const double across = kAcrossGravityMps2[(c / 4) % 2];
    const double start_err_deg = std::atan(across / g) * kDegPerRad;
    const Eigen::Vector3d ext = across * Eigen::Vector3d(std::cos(az), std::sin(az), 0.0);
    const int pushed = c % 2 == 0 ? 1 : static_cast<int>(0.1 * kStartRateHz);
    SelectiveEkf ekf((c / 2) % 2 == 0 ? told : not_told);
    double next_frame_s = kFirstFrameS;
    // WHEN the filter runs over the first seconds
    for (int k = 0; k < n; ++k) {
      ImuSample s;
      s.stamp_ns = int64_t{1'000'000'000} + k * dt_ns;
      const Eigen::Vector3d f = Eigen::Vector3d(0, 0, g) + (k < pushed ? ext : Eigen::Vector3d::Zero());
      s.accel_mps2 = q_true.conjugate() * f + sigma_mps2 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
      s.gyro_rps.setZero();
      EXPECT_TRUE(ekf.update_imu(s));
      if (vision_period_s > 0.0 && k / kStartRateHz >= next_frame_s - 1e-9) {
        next_frame_s += vision_period_s;
        VisionPose v;
        v.capture_stamp_ns = s.stamp_ns;
        v.q_world_camera = q_true;  // q_body_camera identity
        v.has_position = false;
        v.sigma_rad = kFrameSigmaRad;
        EXPECT_TRUE(ekf.update_vision(v));
      }
      const Eigen::Vector3d e = world_attitude_error(ekf.q_world_body(), q_true);
      if (k == 0) {
        r.start_off += std::abs(e.head<2>().norm() * kDegPerRad - start_err_deg) > kStartOracleTolDeg ? 1 : 0;
      }
      // THEN the published tilt covers the tilt's error at every sample
      const Eigen::Matrix2d cov = ekf.predict_horizon().covariance.topLeftCorner<2, 2>();
      const double nees = e.head<2>().dot(cov.inverse() * e.head<2>());
      if (nees > r.worst) {
        r.worst = nees;
        r.worst_t = k / kStartRateHz;
      }
      r.outside += nees > kTilt2Dof95Start ? 1 : 0;
    }
  }
  return r;
}

TEST(SelectiveEkfStart, GivenAStartAtRestWithAnAccelerationAcrossGravityWhenTheFilterRunsThenThePublishedTiltCoversTheTiltErrorAtEverySample) {
  const StartAcrossGravity r = run_starts_across_gravity(0.0);
  std::printf("start with %.1f or %.1f m/s^2 across gravity: tilt NEES at most %.3g (at %.3f s), %d of %d samples above %.3f\n",
              kAcrossGravityMps2[0], kAcrossGravityMps2[1], r.worst, r.worst_t, r.outside, r.samples, kTilt2Dof95Start);
  EXPECT_EQ(r.start_off, 0);
  EXPECT_EQ(r.outside, 0);
}

// The same with vision frames (30 Hz) from 0.05 s, before the start is settled: the bound joins
// P_err at the first frame, whose rows shrink it (it was published unchanged until 0.5 s).
TEST(SelectiveEkfStart, GivenAStartAtRestWithAnAccelerationAcrossGravityWhenVisionComesBeforeItIsSettledThenThePublishedTiltCoversTheTiltErrorAtEverySample) {
  const StartAcrossGravity r = run_starts_across_gravity(1.0 / 30.0);
  std::printf("start with %.1f or %.1f m/s^2 across gravity, vision from 0.05 s: tilt NEES at most %.3g (at %.3f s), %d of %d samples above %.3f\n",
              kAcrossGravityMps2[0], kAcrossGravityMps2[1], r.worst, r.worst_t, r.outside, r.samples, kTilt2Dof95Start);
  EXPECT_EQ(r.start_off, 0);
  EXPECT_EQ(r.outside, 0);
}

}  // namespace
}  // namespace poise
