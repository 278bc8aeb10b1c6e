// The selective EKF's published covariance against the simulated truth (issue 31): NEES of the
// world-frame attitude error over many samples, IMU only and with synthetic vision. Oracles: the
// chi-square law with three degrees of freedom (median 2.366, 95 % of samples at or below 7.815)
// and the bounds the issue sets for correlated samples, against the simulator's truth.
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/eval/selective_ekf_eval.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/sim/sensor_simulator.h"
#include "poise/sim/vision_synth.h"

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <array>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace poise {
namespace {

// Filter errors are correlated over seconds (bias, low-pass lag), so a run of a minute holds a
// few dozen independent samples: the bounds are those the issue sets (median NEES 1-5, 85-99 %
// inside the 95 % ellipsoid), on the samples of every run pooled. The side that matters to a
// consumer is asserted tightly (never claim more than the filter knows: median <= 5, >= 85 %
// inside); on the other side the filter keeps the process noise it is tuned with for real
// sensors (sigma_attitude_walk), which the simulator's ideal gyro does not have, so only a floor
// is asserted there (measured: see the printed figures and ESTIMATORS.md).
constexpr double kMaxMedianNees = 5.0;
constexpr double kMinInside95 = 0.85;
constexpr double kMinMedianNees = 0.05;
constexpr double kBandMinMedianNees = 1.0;  ///< the issue's band, lower side (told the sensor's figures)
constexpr double kBandMaxInside95 = 0.99;   ///< the issue's band, upper side
constexpr double kSkipStartS = 5.0;  ///< s: the scenarios' start at rest, where the field is learnt
constexpr double kRoundingRad2 = 1e-15;  ///< rad^2: rounding of a difference of two covariances

struct Consistency {
  NeesSummary nees;
  double rms_deg = 0.0;
};

/// One simulated sample into the filter, then the vision frames that have arrived by its stamp.
bool update_with_vision(SelectiveEkf& ekf, VisionSynthesizer& synth, const sim::SimSample& s) {
  const bool ok = ekf.update_imu(s.imu);
  synth.push_truth(s.imu.stamp_ns, s.truth.q_world_body, s.truth.p_world_m, true);
  for (const VisionPose& v : synth.pop_arrived(s.imu.stamp_ns)) {
    ekf.update_vision(v);
  }
  return ok;
}

/// Runs the filter over a scenario (with vision when `vision` has a rate); NEES of every sample
/// after kSkipStartS.
Consistency run(const std::string& scenario, uint64_t seed, const SelectiveEkfParams& p, const VisionSynthParams& vision) {
  sim::SensorSimulator simu(sim::make_scenario(scenario, 200.0, seed));
  SelectiveEkf ekf(p);
  VisionSynthParams vp = vision;
  vp.seed = seed;
  std::optional<VisionSynthesizer> synth;
  if (vision.rate_hz > 0.0) {
    synth.emplace(vp);
  }
  Consistency c;
  double sq = 0.0;
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    const bool ok = synth ? update_with_vision(ekf, *synth, s) : ekf.update_imu(s.imu);
    if (!ok || s.truth.t_s < kSkipStartS) {
      continue;
    }
    const Eigen::Vector3d e = world_attitude_error(ekf.q_world_body(), s.truth.q_world_body);
    c.nees.add(attitude_nees(e, ekf.attitude_covariance()));
    sq += e.squaredNorm();
  }
  c.rms_deg = std::sqrt(sq / static_cast<double>(std::max<size_t>(1, c.nees.samples()))) * kDegPerRad;
  return c;
}

/// The default filter told what the simulated sensor is: its gyro noise (0.05 deg/s per sample),
/// no gyro scale error, a constant bias (no random walk).
SelectiveEkfParams told_the_simulated_sensor() {
  SelectiveEkfParams p;
  p.sigma_gyro_rps = 0.05 * kRadPerDeg;
  p.gyro_scale_error = 0.0;
  p.sigma_bias_walk = 0.0;
  return p;
}

/// Pooled NEES over two scenarios and three seeds, each run printed.
NeesSummary pooled_runs(const SelectiveEkfParams& p, const VisionSynthParams& vision, const char* what) {
  NeesSummary pooled;
  for (const char* scenario : {"random_motion", "fast_motion"}) {
    for (uint64_t seed : {1u, 2u, 3u}) {
      const Consistency c = run(scenario, seed, p, vision);
      std::printf("%s, %s seed %llu: RMS error %.3f deg, median NEES %.2f, %.1f %% inside the 95 %% ellipsoid, "
                  "%zu samples\n",
                  what, scenario, static_cast<unsigned long long>(seed), c.rms_deg, c.nees.median(),
                  100.0 * c.nees.fraction_inside(), c.nees.samples());
      EXPECT_EQ(c.nees.without_covariance(), 0u) << scenario << " seed " << seed;
      pooled.merge(c.nees);
    }
  }
  std::printf("%s pooled: median NEES %.2f, %.1f %% inside\n", what, pooled.median(), 100.0 * pooled.fraction_inside());
  return pooled;
}

/// The band on the side that matters to a consumer, and the floor on the other side.
void expect_inside_the_band(const NeesSummary& pooled) {
  EXPECT_LE(pooled.median(), kMaxMedianNees);
  EXPECT_GE(pooled.fraction_inside(), kMinInside95);
  EXPECT_GE(pooled.median(), kMinMedianNees);
}

TEST(SelectiveEkfConsistency, GivenASensorWithKnownNoiseWhenMovingImuOnlyThenTheNeesIsInsideTheBounds) {
  // GIVEN the simulator's sensor: white gyro 0.05 deg/s, accelerometer 0.04 m/s^2, magnetometer
  // 0.2 uT per sample, a constant gyro bias, external accelerations; no magnet; the filter told
  // what that sensor is, no vision
  VisionSynthParams none;
  none.rate_hz = 0.0;
  // WHEN the filter runs over two scenarios, three seeds each
  // THEN over every sample the NEES is inside the band on the side that matters to a consumer
  expect_inside_the_band(pooled_runs(told_the_simulated_sensor(), none, "IMU only"));
}

/// The default filter told the simulated sensor's own figures, which only the published
/// covariance reads: its gyro and accelerometer noise densities (0.05 deg/s and 0.04 m/s^2 per
/// sample at 200 Hz), a constant bias, no gyro scale error; and its samples' timing (the rate at
/// the stamp, no delay: imu_delay_s 0).
SelectiveEkfParams told_the_simulated_sensor_figures() {
  SelectiveEkfParams p;
  p.gyro_noise_density_rps_per_sqrt_hz = 0.05 * kRadPerDeg / std::sqrt(200.0);
  p.accel_noise_density_mps2_per_sqrt_hz = 0.04 / std::sqrt(200.0);
  p.gyro_bias_walk_rps_per_sqrt_s = 0.0;
  p.gyro_scale_error = 0.0;
  p.imu_delay_s = 0.0;
  return p;
}

TEST(SelectiveEkfConsistency, GivenTheSensorFiguresWhenMovingWithExternalAccelerationImuOnlyThenTheNeesIsInsideTheBand) {
  // GIVEN the simulator's moving scenarios (external accelerations up to 3 and 12 m/s^2 that the
  // accelerometer low-pass lets through in part), no vision, the filter told the sensor's figures:
  // the tilt rows then carry no white noise in P_err and the external acceleration's error is
  // its own term (SelectiveEkfState::ext_accel_error; without it: pooled median 4.86, 76.5 %)
  VisionSynthParams none;
  none.rate_hz = 0.0;
  // WHEN the filter runs over two scenarios, three seeds each
  const NeesSummary pooled = pooled_runs(told_the_simulated_sensor_figures(), none, "IMU only, figures told");
  // THEN over every sample the NEES is inside the band on both sides
  EXPECT_LE(pooled.median(), kMaxMedianNees);
  EXPECT_GE(pooled.median(), kBandMinMedianNees);
  EXPECT_GE(pooled.fraction_inside(), kMinInside95);
  EXPECT_LE(pooled.fraction_inside(), kBandMaxInside95);
}

TEST(SelectiveEkfConsistency, GivenASensorWithKnownNoiseWhenMovingWithVisionThenTheNeesIsInsideTheBounds) {
  // GIVEN the same sensor and the hybrid benchmark's vision: 30 Hz, 50 ms late, 1 deg / 1 cm,
  // 30 % of the time hidden in bursts of 1-5 s
  // WHEN the filter runs over two scenarios, three seeds each (the vision's seed the run's)
  // THEN over every sample the NEES is inside the band on the side that matters to a consumer
  expect_inside_the_band(pooled_runs(told_the_simulated_sensor(), hybrid_benchmark_vision(), "with vision"));
}

TEST(SelectiveEkfConsistency, GivenAMagnetWhenTheMagnetometerIsGatedThenTheHeadingVarianceGrowsAndFallsWhenTrustedAgain) {
  // GIVEN a static sensor and a magnet from 15 s (3 s approach, 15 s held, then leaving)
  constexpr double kBeforeS = 14.0;   ///< s: clean field, magnetometer trusted
  constexpr double kGatedFromS = 19.0;  ///< s: the magnet held for 1 s, the magnetometer gated
  constexpr double kGatedS = 32.0;    ///< s: the magnet held for 14 s
  constexpr double kAfterS = 48.0;    ///< s: the magnet gone for about 10 s
  sim::SensorSimulator simu(sim::make_scenario("static_magnet", 100.0, 1));
  SelectiveEkf ekf;
  double before = 0.0;
  double gated_from = 0.0;
  double gated = 0.0;
  double after = 0.0;
  bool trusted_when_gated = true;
  bool trusted_from = true;
  // WHEN the filter runs over it
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    ASSERT_TRUE(ekf.update_imu(s.imu) || !ekf.initialized());
    const double t = s.truth.t_s;
    const double var_heading = ekf.attitude_covariance()(2, 2);  // rad^2
    if (t <= kBeforeS) {
      before = var_heading;
    } else if (t <= kGatedFromS) {
      gated_from = var_heading;
      trusted_from = ekf.mag_status().trusted;
    } else if (t <= kGatedS) {
      gated = var_heading;
      trusted_when_gated = ekf.mag_status().trusted;
    } else if (t <= kAfterS) {
      after = var_heading;
    }
  }
  std::printf("heading sigma: %.3f deg before, %.3f deg gated from, %.3f deg gated, %.3f deg after\n",
              std::sqrt(before) * kDegPerRad, std::sqrt(gated_from) * kDegPerRad, std::sqrt(gated) * kDegPerRad,
              std::sqrt(after) * kDegPerRad);
  // THEN the magnetometer was gated, the heading variance grew meanwhile and fell once it was
  // trusted again. (Grew over the gated time, not against the clean field before: at rest the
  // zero-rate row holds the heading, so it grows by the attitude walk alone, 0.05 deg here, less
  // than the accepted field's disturbance term the clean field carried and the gated one drops.)
  EXPECT_FALSE(trusted_from);
  EXPECT_FALSE(trusted_when_gated);
  EXPECT_GT(gated, gated_from);
  EXPECT_LT(after, gated);
}

TEST(SelectiveEkfHeadingStatus, GivenAMagnetWhenTheMagnetometerIsGatedThenTheHeadingIsUnverifiedUntilTrustedAgain) {
  // GIVEN a static sensor and a magnet from 15 s (3 s approach, 15 s held, then leaving)
  constexpr double kHeldFromS = 20.0;  ///< s: inside the hold
  constexpr double kHeldToS = 32.0;
  constexpr double kCleanFromS = 40.0;  ///< s: the magnet gone, before the second one (50 s)
  constexpr double kCleanToS = 49.0;
  constexpr double kLearningS = 0.5;    ///< s: the field reference being learnt (field_startup_s 1 s)
  // s: learnt over field_startup_s (1 s), then accepted for field_verify_s (5 s) against it, with
  // a margin of one aiding step
  const double kLearntS = 1.0 + SelectiveEkfParams{}.field_verify_s + 0.1;
  constexpr double kCleanBeforeToS = 14.0;  ///< s: before the magnet approaches (15 s)
  sim::SensorSimulator simu(sim::make_scenario("static_magnet", 100.0, 1));
  SelectiveEkf ekf;
  SelectiveEkfParams six_axis_params;
  six_axis_params.use_magnetometer = MagnetometerUse::kOff;
  SelectiveEkf six_axis(six_axis_params);
  EXPECT_EQ(ekf.heading_status(), HeadingStatus::kNoReference) << "before the first sample";
  int verified_clean = 0, clean = 0, unverified_held = 0, held = 0, six_axis_no_reference = 0, samples = 0;
  HeadingStatus learning = HeadingStatus::kVerified;
  // WHEN the filters run over it
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    ekf.update_imu(s.imu);
    six_axis.update_imu(s.imu);
    const double t = s.truth.t_s;
    const HeadingStatus h = ekf.heading_status();
    if (t <= kLearningS) {
      learning = h;
    }
    if (t >= kLearntS && t < kCleanBeforeToS) {
      verified_clean += h == HeadingStatus::kVerified;
      ++clean;
    } else if (t >= kHeldFromS && t <= kHeldToS) {
      unverified_held += h == HeadingStatus::kUnverified;
      ++held;
    } else if (t >= kCleanFromS && t <= kCleanToS) {
      verified_clean += h == HeadingStatus::kVerified;
      ++clean;
    }
    six_axis_no_reference += six_axis.heading_status() == HeadingStatus::kNoReference;
    ++samples;
  }
  // THEN the heading is unverified while the field reference is learnt and while the magnet is
  // held, verified in the clean field before and after it, and a 6-axis filter has no reference
  EXPECT_EQ(learning, HeadingStatus::kUnverified) << "the reference is still being learnt";
  EXPECT_EQ(unverified_held, held);
  EXPECT_EQ(verified_clean, clean);
  EXPECT_EQ(six_axis_no_reference, samples);
}

TEST(SelectiveEkfHeadingStatus, GivenVisionWhenTheMagnetometerIsGatedThenTheHeadingIsVerifiedByVision) {
  // GIVEN the same magnet and the hybrid benchmark's vision without dropouts
  constexpr double kHeldFromS = 20.0;  ///< s: inside the hold
  constexpr double kHeldToS = 32.0;
  sim::SensorSimulator simu(sim::make_scenario("static_magnet", 100.0, 1));
  SelectiveEkf ekf;
  VisionSynthParams vp = hybrid_benchmark_vision();
  vp.dropout_fraction = 0.0;
  VisionSynthesizer synth(vp);
  int verified_held = 0, held = 0;
  // WHEN the filter runs over it with vision
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    update_with_vision(ekf, synth, s);
    if (s.truth.t_s >= kHeldFromS && s.truth.t_s <= kHeldToS) {
      verified_held += ekf.heading_status() == HeadingStatus::kVerified;
      ++held;
    }
  }
  // THEN the tag map verifies the heading all along the hold
  EXPECT_EQ(verified_held, held);
}

TEST(SelectiveEkfConsistency, GivenVisionWhenRunThenThePoseCovarianceCarriesThePublishedAttitudeCovariance) {
  // GIVEN the filter with the hybrid benchmark's vision in fast motion
  constexpr double kNearPublished = 0.01;  ///< of the published trace: the part left out (delay, blend rotation)
  sim::SensorSimulator simu(sim::make_scenario("fast_motion", 200.0, 1));
  SelectiveEkf ekf;
  VisionSynthesizer synth(hybrid_benchmark_vision());
  int checked = 0;
  // WHEN it runs
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    update_with_vision(ekf, synth, s);
    if (!ekf.initialized()) {
      continue;
    }
    const Eigen::Matrix<double, 9, 9> pose = pose_covariance_world(ekf);
    const Eigen::Matrix<double, 9, 9> state = pose_covariance_world(ekf.state(), ekf.q_world_body());
    const Eigen::Matrix3d published = attitude_covariance_world(ekf);
    // THEN the pose covariance stays positive semi-definite, its attitude block is never below the
    // state's and equals the published one but for a sliver
    using Solver9 = Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>>;
    ASSERT_GE(Solver9(pose).eigenvalues().minCoeff(), -kRoundingRad2);
    const Eigen::Matrix3d raised = pose.bottomRightCorner<3, 3>() - state.bottomRightCorner<3, 3>();
    ASSERT_GE(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(raised).eigenvalues().minCoeff(), -kRoundingRad2);
    const Eigen::Matrix3d left_out = published - pose.bottomRightCorner<3, 3>();
    ASSERT_LE(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(left_out).eigenvalues().cwiseAbs().maxCoeff(),
              kNearPublished * published.trace());
    ++checked;
  }
  EXPECT_GT(checked, 0);
}

TEST(SelectiveEkfConsistency, GivenAnyGyroScaleErrorWhenRunThenTheEstimateIsTheSameAndOnlyThePublishedCovarianceDiffers) {
  // GIVEN two filters that differ only in the scale error their published covariance allows for
  SelectiveEkfParams none;
  none.gyro_scale_error = 0.0;
  SelectiveEkf a(none);
  SelectiveEkf b;  // the default, 0.5 %
  sim::SensorSimulator simu(sim::make_scenario("fast_motion", 200.0, 1));
  double largest_difference = 0.0;
  // WHEN both run over the same samples
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    a.update_imu(s.imu);
    b.update_imu(s.imu);
    // THEN every estimate is the same, bit for bit
    ASSERT_EQ(a.q_world_body().coeffs(), b.q_world_body().coeffs());
    if (a.initialized()) {
      const Eigen::Matrix3d d = b.attitude_covariance() - a.attitude_covariance();
      // AND the covariance that allows for a scale error is never the smaller one
      ASSERT_GE(d.selfadjointView<Eigen::Lower>().eigenvalues().minCoeff(), -kRoundingRad2);
      largest_difference = std::max(largest_difference, d.trace());
    }
  }
  // AND over a fast rotation it is larger
  EXPECT_GT(largest_difference, 0.0);
}

/// A scripted motion (not the simulator's random one, so that each body axis' rotation is known):
/// at rest with body x up and body y along magnetic north, a roll about north (body y, 0.5 Hz,
/// 57 deg each way), rest, a spin about the vertical on body x (+720 deg), a turn over onto body z,
/// a spin back on body z (-720 deg), rest. The field 50 uT at 60 deg dip (simulator's), white noise
/// as the simulator's sensor, 200 Hz.
struct ScriptedSegment {
  double duration_s;
  Eigen::Vector3d body_rate_rps;
  double oscillation_hz;  ///< 0: constant rate; else the rate times cos(2 pi f t)
};

constexpr double kScriptedDtS = 0.005;  ///< s: the scripted motion's sample interval (200 Hz)

std::vector<ImuSample> spin_and_roll_samples(std::vector<Eigen::Quaterniond>& truth) {
  constexpr double kRateHz = 1.0 / kScriptedDtS;
  constexpr double kDt = kScriptedDtS;
  const double w = 90.0 * kRadPerDeg;
  const std::array<ScriptedSegment, 7> segments{{{30.0, {0, 0, 0}, 0.0},
                                                 {10.0, {0, kPi, 0}, 0.5},
                                                 {5.0, {0, 0, 0}, 0.0},
                                                 {8.0, {w, 0, 0}, 0.0},
                                                 {1.0, {0, 0.5 * kPi, 0}, 0.0},
                                                 {8.0, {0, 0, -w}, 0.0},
                                                 {20.0, {0, 0, 0}, 0.0}}};
  const sim::MagneticEnvironment field;
  const sim::SensorNoise noise;
  std::mt19937 rng(1);
  std::normal_distribution<double> n01(0.0, 1.0);
  auto white = [&](double sd) { return Eigen::Vector3d(sd * n01(rng), sd * n01(rng), sd * n01(rng)); };
  Eigen::Quaterniond q(Eigen::AngleAxisd(-0.5 * kPi, Eigen::Vector3d::UnitY()));  // body x up
  std::vector<ImuSample> out;
  for (const ScriptedSegment& sg : segments) {
    const long n = std::lround(sg.duration_s * kRateHz);
    for (long i = 0; i < n; ++i) {
      const double f = sg.oscillation_hz > 0.0 ? std::cos(2.0 * kPi * sg.oscillation_hz * (i + 0.5) * kDt) : 1.0;
      const Eigen::Vector3d wb = f * sg.body_rate_rps;
      q = (q * quat_exp(wb * kDt)).normalized();
      ImuSample x;
      x.seq = static_cast<uint32_t>(out.size());
      x.stamp_ns = 1'000'000'000 + static_cast<int64_t>(out.size()) * 5'000'000;
      x.gyro_rps = wb + white(noise.sigma_gyro_rps);
      x.accel_mps2 = q.conjugate() * Eigen::Vector3d(0.0, 0.0, 9.80665) + white(noise.sigma_accel_mps2);
      x.mag_ut = q.conjugate() * field.field_world_ut() + white(noise.sigma_mag_ut);
      x.has_mag = true;
      out.push_back(x);
      truth.push_back(q);
    }
  }
  return out;
}

TEST(SelectiveEkfConsistency, GivenEachGyroAxisItsOwnScaleErrorWhenSpinningAndRollingThenThePublishedHeadingTermIsTheirSpread) {
  // GIVEN the scripted spin-and-roll motion and a gyro whose three axes are each off by +-0.5 %
  // (the default allowance, gyro_scale_error), in all eight sign combinations: the heading's
  // spread over them is the variance an allowance of 0.5 % on each axis, independent, stands for
  constexpr double kScale = 0.005;
  constexpr double kRestEndS = 30.0;  ///< s: the start at rest
  // tolerances: the term is first order in s; at 720 deg turns s X = 0.063 rad, so the realized
  // responses differ from it by about that fraction; doubled for the heading lag taken as P / q
  // (measured: within 8 %)
  constexpr double kRelTol = 0.15;
  // deg: the smallest difference asserted, 1/30 of the heading's own sigma at rest (0.6 deg)
  constexpr double kAbsTolDeg = 0.02;
  // the heading's 1-dof 95 % bound, and the floor for correlated samples
  constexpr double kBound95Sigma = 1.96;
  constexpr double kMinCovered = 0.85;
  std::vector<Eigen::Quaterniond> truth;
  const std::vector<ImuSample> samples = spin_and_roll_samples(truth);
  SelectiveEkfParams no_allowance;
  no_allowance.gyro_scale_error = 0.0;
  const SelectiveEkfParams allowance;  // 0.5 % per axis
  ASSERT_EQ(allowance.gyro_scale_error, kScale);
  SelectiveEkf exact(no_allowance), exact_allowing(allowance);
  std::vector<SelectiveEkf> scaled(8, SelectiveEkf(allowance));
  size_t checked = 0, off = 0, scored = 0;
  double first_off_s = -1.0;
  std::array<size_t, 8> covered{};
  double largest_spread_deg = 0.0;
  // WHEN the filters run: one on the exact gyro, eight on the scaled ones
  for (size_t k = 0; k < samples.size(); ++k) {
    const ImuSample& x = samples[k];
    const double t_s = static_cast<double>(k) * kScriptedDtS;
    exact.update_imu(x);
    exact_allowing.update_imu(x);
    double spread = 0.0;
    for (size_t c = 0; c < scaled.size(); ++c) {
      ImuSample y = x;
      for (int a = 0; a < 3; ++a) {
        y.gyro_rps[a] *= 1.0 + (((c >> a) & 1u) ? kScale : -kScale);
      }
      scaled[c].update_imu(y);
      if (!exact.initialized() || t_s < kRestEndS) {
        continue;
      }
      spread += std::pow(world_attitude_error(scaled[c].q_world_body(), exact.q_world_body()).z(), 2);
      const Eigen::Vector3d e = world_attitude_error(scaled[c].q_world_body(), truth[k]);
      covered[c] += std::abs(e.z()) <= kBound95Sigma * std::sqrt(scaled[c].attitude_covariance()(2, 2));
      scored += c == 0;
    }
    if (!exact.initialized() || t_s < kRestEndS) {
      continue;
    }
    // THEN the published heading term (the allowance's share of the heading variance) is the spread
    const double spread_deg = std::sqrt(spread / static_cast<double>(scaled.size())) * kDegPerRad;
    const double term = exact_allowing.attitude_covariance()(2, 2) - exact.attitude_covariance()(2, 2);
    const double term_deg = std::sqrt(std::max(0.0, term)) * kDegPerRad;
    if (std::abs(term_deg - spread_deg) > kRelTol * spread_deg + kAbsTolDeg) {
      first_off_s = off++ == 0 ? t_s : first_off_s;
    }
    largest_spread_deg = std::max(largest_spread_deg, spread_deg);
    ++checked;
  }
  std::printf("scale-error spread up to %.2f deg; the term off it at %zu of %zu instants (first %.2f s)\n",
              largest_spread_deg, off, checked, first_off_s);
  EXPECT_EQ(off, 0u) << "first at " << first_off_s << " s";
  EXPECT_GT(largest_spread_deg, 1.0);  // the spins turn the heading by degrees
  // AND every scaled run's heading error (against the truth) is covered by its published variance
  for (size_t c = 0; c < covered.size(); ++c) {
    const double inside = static_cast<double>(covered[c]) / static_cast<double>(scored);
    std::printf("  signs %c%c%c: heading within %.2f sigma in %.1f %% of %zu samples\n", (c & 1u) ? '+' : '-',
                (c & 2u) ? '+' : '-', (c & 4u) ? '+' : '-', kBound95Sigma, 100.0 * inside, scored);
    EXPECT_GE(inside, kMinCovered) << "signs " << c;
  }
}

}  // namespace
}  // namespace poise
