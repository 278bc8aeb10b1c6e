// Issue 36: the camera-IMU time offset estimated online and the prediction to a requested time.
// Oracles: a synthetic rotation about a fixed axis, angle A sin(2 pi f t) (attitude and rate in
// closed form), frames stamped with a known offset; a constant-rate rotation whose rotation over a
// horizon is exp(w H).
#include "poise/core/attitude.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/selective_ekf/vision_time_offset.h"
#include "poise/sim/vision_synth.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <limits>
#include <random>
#include <stdexcept>

namespace poise {
namespace {

constexpr double kImuHz = 200.0;
constexpr double kCameraHz = 30.0;
constexpr double kAmplitudeRad = 0.8;   // head turning +-46 deg
constexpr double kFreqHz = 0.4;
constexpr double kTrueOffsetS = -0.030;  // the camera stamps 30 ms after the exposure
/// tolerance of the converged offset, s (frames with 1 deg noise, 20 s of motion)
constexpr double kOffsetTolS = 0.001;

const Eigen::Vector3d kAxis = Eigen::Vector3d(0.3, 0.5, 0.8).normalized();

double angle_at(double t) { return kAmplitudeRad * std::sin(2.0 * kPi * kFreqHz * t); }
double rate_at(double t) { return kAmplitudeRad * 2.0 * kPi * kFreqHz * std::cos(2.0 * kPi * kFreqHz * t); }
Eigen::Quaterniond attitude_at(double t) { return Eigen::Quaterniond(Eigen::AngleAxisd(angle_at(t), kAxis)); }

int64_t ns(double s) { return static_cast<int64_t>(std::llround(s * 1e9)); }

ImuSample imu_at(double t, const Eigen::Vector3d& rate_body) {
  ImuSample s;
  s.stamp_ns = ns(t);
  s.gyro_rps = rate_body;
  s.accel_mps2 = attitude_at(t).conjugate() * Eigen::Vector3d(0.0, 0.0, 9.81);
  return s;
}

/// A camera frame of the synthetic rotation at true time t, stamped t - offset, 1 deg noise.
VisionPose frame_at(double t, std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0 * kRadPerDeg);
  VisionPose v;
  v.capture_stamp_ns = ns(t - kTrueOffsetS);
  v.q_world_camera = attitude_at(t) * quat_exp(Eigen::Vector3d(n(rng), n(rng), n(rng)));
  v.has_position = false;
  return v;
}

TEST(VisionTimeOffset, GivenASyntheticRotationWithAKnownOffsetWhenEstimatedThenItConvergesToIt) {
  VisionTimeOffsetParams p;
  p.prior_sigma_s = 0.05;
  VisionTimeOffsetEstimator est(p);
  std::mt19937_64 rng(3);
  const double frame_dt = 1.0 / kCameraHz;
  double next_frame = 0.5;
  for (int k = 0; k <= static_cast<int>(20.0 * kImuHz); ++k) {
    const double t = k / kImuHz;
    est.add_gyro(ns(t), kAxis * rate_at(t));
    // frames arrive 50 ms after their true time
    while (next_frame + 0.05 <= t) {
      const VisionPose v = frame_at(next_frame, rng);
      est.add_frame(v.capture_stamp_ns, v.q_world_camera, 1.0 * kRadPerDeg);
      next_frame += frame_dt;
    }
  }
  const VisionTimeOffsetStatus& st = est.status();
  EXPECT_NEAR(st.offset_s, kTrueOffsetS, kOffsetTolS);
  EXPECT_TRUE(st.converged);
  EXPECT_LT(st.sigma_s, p.converged_sigma_s);
  // the reported sigma is honest: the error within 4 sigma
  EXPECT_LT(std::abs(st.offset_s - kTrueOffsetS), 4.0 * st.sigma_s);
  EXPECT_GT(st.used, 300U);
  EXPECT_EQ(st.rejected, 0U);
}

/// The largest |offset error| / sigma over a run of the synthetic rotation whose gyro keeps a bias
/// error `bias_err` (a filter that has not learnt its bias), the estimator told `bias_cov`.
double worst_error_in_sigmas(const Eigen::Vector3d& bias_err, const Eigen::Matrix3d& bias_cov, double run_s) {
  constexpr double kFrameSigmaRad = 0.1 * kRadPerDeg;  // a precise camera (the simulated one's order)
  VisionTimeOffsetParams p;
  p.prior_sigma_s = 0.05;
  VisionTimeOffsetEstimator est(p);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> n(0.0, kFrameSigmaRad);
  double next_frame = 0.5;
  double worst = 0.0;
  for (int k = 0; k <= static_cast<int>(run_s * kImuHz); ++k) {
    const double t = k / kImuHz;
    est.add_gyro(ns(t), kAxis * rate_at(t) + bias_err, bias_cov);
    while (next_frame + 0.05 <= t) {
      const Eigen::Quaterniond q = attitude_at(next_frame) * quat_exp(Eigen::Vector3d(n(rng), n(rng), n(rng)));
      est.add_frame(ns(next_frame - kTrueOffsetS), q, kFrameSigmaRad);
      next_frame += 1.0 / kCameraHz;
      if (est.status().used > 0) {
        worst = std::max(worst, std::abs(est.status().offset_s - kTrueOffsetS) / est.status().sigma_s);
      }
    }
  }
  return worst;
}

TEST(VisionTimeOffset, GivenAGyroBiasNotYetLearntWhenItsCovarianceIsGivenThenTheOffsetsSigmaCoversItsError) {
  // GIVEN a gyro bias error of 0.57 deg/s (the selective EKF's init_sigma_bias_rps: a cold start)
  // about the rotation axis, the direction the pairs' Jacobian has, and a precise camera
  constexpr double kBiasSigmaRps = 0.01;
  constexpr double kMaxSigmas = 3.0;  // the error within 3 sigma at every frame
  constexpr double kRunS = 10.0;
  const Eigen::Vector3d bias_err = kBiasSigmaRps * kAxis;
  const Eigen::Matrix3d bias_cov = kBiasSigmaRps * kBiasSigmaRps * Eigen::Matrix3d::Identity();
  // WHEN the estimator is told the bias's covariance, and (the former use) is not
  const double told = worst_error_in_sigmas(bias_err, bias_cov, kRunS);
  const double not_told = worst_error_in_sigmas(bias_err, Eigen::Matrix3d::Zero(), kRunS);
  std::printf("offset error / sigma at most: bias covariance told %.2f, not told %.2f\n", told, not_told);
  // THEN told, its sigma covers the error the bias causes (not told: 3.73 sigma)
  EXPECT_LE(told, kMaxSigmas);
  EXPECT_GT(not_told, told);
}

TEST(VisionTimeOffset, GivenNoRotationWhenFramesArriveThenNothingIsLearntAndItSaysNoMotion) {
  VisionTimeOffsetParams p;
  p.prior_sigma_s = 0.05;
  VisionTimeOffsetEstimator est(p);
  for (int k = 0; k <= static_cast<int>(5.0 * kImuHz); ++k) {
    const double t = k / kImuHz;
    est.add_gyro(ns(t), Eigen::Vector3d::Zero());
    if (k % 7 == 0 && t > 0.1) {
      est.add_frame(ns(t - 0.05), Eigen::Quaterniond::Identity(), 0.01);
    }
  }
  EXPECT_EQ(est.status().used, 0U);
  EXPECT_EQ(est.status().last, TimeOffsetDecision::kNoMotion);
  EXPECT_DOUBLE_EQ(est.status().offset_s, 0.0);
  EXPECT_FALSE(est.status().converged);
}

TEST(VisionTimeOffset, GivenTheSelectiveEkfWithWrongCameraStampsWhenEstimatingThenTheOffsetConvergesAndVisionIsFusedOnTime) {
  auto run = [](double sigma_s, double& final_err_deg) {
    SelectiveEkfParams p;
    p.vision_time_offset_sigma_s = sigma_s;
    p.imu_delay_s = 0.0;  // the samples describe the motion at their stamps (else half a sample is in the offset)
    SelectiveEkf ekf(p);
    std::mt19937_64 rng(5);
    double next_frame = 0.2;
    double sq = 0.0;
    int n = 0;
    for (int k = 0; k <= static_cast<int>(30.0 * kImuHz); ++k) {
      const double t = k / kImuHz;
      ekf.update_imu(imu_at(t, kAxis * rate_at(t)));
      while (next_frame + 0.05 <= t) {
        ekf.update_vision(frame_at(next_frame, rng));
        next_frame += 1.0 / kCameraHz;
      }
      if (t > 20.0) {
        const double e = quat_angle_between(ekf.q_world_body(), attitude_at(t)) * kDegPerRad;
        sq += e * e;
        ++n;
      }
    }
    final_err_deg = std::sqrt(sq / n);
    return ekf.vision_time_offset();
  };
  double err_est = 0.0;
  double err_none = 0.0;
  const VisionTimeOffsetStatus st = run(0.05, err_est);
  run(0.0, err_none);
  EXPECT_NEAR(st.offset_s, kTrueOffsetS, kOffsetTolS);
  EXPECT_TRUE(st.converged);
  // over the last 10 s: the estimate fuses frames at their true time (RMS below 0.5 deg), the
  // uncompensated filter fuses them 30 ms late (|w| up to 2 rad/s: about 1-3 deg)
  constexpr double kOnTimeRmsDeg = 0.5;
  EXPECT_LT(err_est, kOnTimeRmsDeg);
  EXPECT_GT(err_none, 2.0 * err_est);
}

TEST(SelectiveEkfPredict, GivenAConstantRateRotationWhenPredictedThenItEqualsTheAnalyticRotationAtTheHorizon) {
  SelectiveEkf ekf;
  const Eigen::Vector3d w(0.2, -0.4, 1.0);  // rad/s, body
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  const double dt = 1.0 / kImuHz;
  for (int k = 0; k <= static_cast<int>(10.0 * kImuHz); ++k) {
    ImuSample s;
    s.stamp_ns = ns(k * dt);
    s.gyro_rps = w;
    s.accel_mps2 = q.conjugate() * Eigen::Vector3d(0.0, 0.0, 9.81);
    ASSERT_TRUE(ekf.update_imu(s));
    q = (q * quat_exp(w * dt)).normalized();
  }
  const int64_t newest = ns(10.0);
  const Eigen::Quaterniond now = ekf.q_world_body();
  const PredictedAttitude at0 = ekf.predict(newest);
  EXPECT_EQ(at0.stamp_ns, newest);
  EXPECT_DOUBLE_EQ(at0.horizon_s, 0.0);
  EXPECT_LT(quat_angle_between(at0.q_world_body, now), 1e-12);
  // tolerance: the filter's rate estimate against the exact gyro (bias state, rate noise), deg
  constexpr double kPredictTolDeg = 0.01;
  double previous_trace = at0.covariance.trace();
  for (double h : {0.01, 0.02, 0.04}) {
    const PredictedAttitude p = ekf.predict(newest + ns(h));
    const Eigen::Quaterniond analytic = now * Eigen::Quaterniond(Eigen::AngleAxisd(w.norm() * h, w.normalized()));
    EXPECT_LT(quat_angle_between(p.q_world_body, analytic) * kDegPerRad, kPredictTolDeg) << "horizon " << h;
    EXPECT_NEAR(p.horizon_s, h, 1e-9);
    // the covariance grows with the horizon and stays symmetric
    EXPECT_GT(p.covariance.trace(), previous_trace) << "horizon " << h;
    EXPECT_LT((p.covariance - p.covariance.transpose()).norm(), 1e-15);
    previous_trace = p.covariance.trace();
  }
  // an instant before the newest sample: the newest output, not extrapolated backwards
  const PredictedAttitude past = ekf.predict(newest - ns(0.1));
  EXPECT_EQ(past.stamp_ns, newest);
  EXPECT_LT(quat_angle_between(past.q_world_body, now), 1e-12);
}

TEST(SelectiveEkfPredict, GivenHostileOffsetsAndHorizonsInTheConfigWhenValidatedThenEachIsRefusedNamingTheKey) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Case {
    const char* key;
    void (*set)(SelectiveEkfParams&, double);
  };
  const Case cases[] = {
      {"vision_time_offset_s", [](SelectiveEkfParams& p, double v) { p.vision_time_offset_s = v; }},
      {"vision_time_offset_sigma_s", [](SelectiveEkfParams& p, double v) { p.vision_time_offset_sigma_s = v; }},
      {"vision_time_offset_walk_s_sqrt_s",
       [](SelectiveEkfParams& p, double v) { p.vision_time_offset_walk_s_sqrt_s = v; }},
      {"predict_horizon_s", [](SelectiveEkfParams& p, double v) { p.predict_horizon_s = v; }},
  };
  for (const Case& c : cases) {
    for (double bad : {nan, inf, -inf, 1e9, -1e9}) {
      SelectiveEkfParams p;
      c.set(p, bad);
      try {
        validate(p);
        ADD_FAILURE() << c.key << " = " << bad << " accepted";
      } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find(c.key), std::string::npos) << e.what();
      }
    }
  }
  SelectiveEkfParams negative;
  negative.predict_horizon_s = -0.01;
  EXPECT_THROW(validate(negative), std::invalid_argument);
  VisionSynthParams v;
  v.stamp_offset_ms = nan;
  EXPECT_THROW(VisionSynthesizer{v}, std::invalid_argument);
  v.stamp_offset_ms = 5000.0;
  EXPECT_THROW(VisionSynthesizer{v}, std::invalid_argument);
}

}  // namespace
}  // namespace poise
