// Cross-validated parameter choice (grid, folds, config writing), trial resampling, and the
// default parallel KF on BROAD against independent oracles (VQF's published figures, the
// rate-independence bound of issue 14).
#include "poise/eval/broad.h"
#include "poise/eval/crossval.h"
#include "poise/eval/filter_registry.h"
#include "poise/eval/runner.h"

#include "poise/core/attitude.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace poise::eval {
namespace {

constexpr double kExactRad = 1e-9;        // resampling of an exactly representable rotation, rad
constexpr double kExactRps = 1e-9;        // ... and of its rate, rad/s
constexpr double kRateChangeTol = 0.15;   // issue 14: RMSE change at 100 Hz / 1 kHz, relative
// (Session 11 added an absolute floor of 0.2 deg here: trial 32 was 0.916 deg at its native rate
// and 1.070 at 1 kHz. The cause was the hard-iron estimate's pairing: it compared the first sample
// at least lag_s after the last comparison, so which readings were paired, and with them the
// estimate's noise, depended on where the samples fell; moving the pairs by a phase alone moves 32
// between 0.82 and 1.00 deg. It now compares readings interpolated at multiples of lag_s, the same
// instants at any rate, and the floor is gone: 1.026 / 0.941 / 1.070 deg.)
// VQF (Laidig & Seel 2023), mean total RMSE on the 19 BROAD trials in ../shared, as published with
// the benchmark's metric (shared/docs/ESTIMATORS.md section 7).
constexpr double kVqfUndisturbedDeg = 1.64;
constexpr double kVqfDisturbedDeg = 3.33;
constexpr double kVqfInclUndisturbedDeg = 0.55;
constexpr double kVqfInclDisturbedDeg = 0.82;
// VQF (real time) on the same 19 trials at every 3rd (95.2 Hz) and every 7th (40.8 Hz) sample, mean
// total RMSE undisturbed / disturbed, as measured for issue 32 (notes/issues/32.md): another
// algorithm on the same decimated data, the oracle of the decimated-rate test.
constexpr double kVqf95UndisturbedDeg = 1.68;
constexpr double kVqf95DisturbedDeg = 3.38;
constexpr double kVqf41UndisturbedDeg = 2.41;
constexpr double kVqf41DisturbedDeg = 4.90;
// The tilt mechanism (accelerometer low-passed in an almost inertial frame, 3 s) is VQF's; with the
// sensor's group delay compensated (BROAD's calibrated 4.18 ms) the inclination beats VQF's.

TrialResult result(int number, double total) {
  TrialResult r;
  r.stem = "t" + std::to_string(number);
  r.number = number;
  r.disturbed = number >= 24;
  r.errors.total_deg = total;
  r.errors.samples = 100;  // scored
  return r;
}

TEST(Grid, ParsesAxesAndRefusesMalformedSpecs) {
  const auto axes = parse_grid({"a=1,2", "tilt.b=x,y,z"});
  ASSERT_EQ(axes.size(), 2u);
  EXPECT_EQ(axes[1].key, "tilt.b");
  EXPECT_EQ(axes[1].values.size(), 3u);
  const auto pts = grid_points(axes);
  ASSERT_EQ(pts.size(), 6u);
  EXPECT_EQ(describe(pts[0]), "a=1 tilt.b=x");
  EXPECT_EQ(describe(pts[5]), "a=2 tilt.b=z");  // first axis slowest
  EXPECT_EQ(grid_points({}).size(), 1u);
  for (const char* bad : {"a", "=1", "a=", "a=1,,2", "a=1,"}) {
    EXPECT_THROW(parse_grid({bad}), std::invalid_argument) << bad;
  }
  EXPECT_THROW(parse_grid({"a=1", "a=2"}), std::invalid_argument);
  EXPECT_THROW(parse_grid({"a=1,2,3", "b=1,2,3"}, 8), std::invalid_argument);
}

TEST(CrossValidation, GivenACandidateThatWinsOnlyThroughOneTrialWhenThatTrialIsHeldOutThenItIsNotChosenForIt) {
  // GIVEN two candidates on four trials (two undisturbed, two disturbed). Candidate 1 is better on
  // trial 1 by a lot and worse elsewhere by a little, so it wins in-sample only because of trial 1.
  const std::vector<std::vector<TrialResult>> by = {
      {result(1, 3.0), result(2, 1.0), result(24, 2.0), result(25, 2.0)},
      {result(1, 1.0), result(2, 1.2), result(24, 2.2), result(25, 2.2)},
  };
  // WHEN cross-validated leaving one trial out
  const CrossValidation cv = cross_validate(by, 0);
  // THEN in-sample candidate 1 wins: objective (1.1 + 2.2) / 2 = 1.65 against (2.0 + 2.0) / 2 = 2.0
  EXPECT_EQ(cv.in_sample_choice, 1u);
  EXPECT_EQ(cv.folds, 4);
  // ... but with trial 1 held out candidate 0 wins on the rest (1.0 / 2.0 against 1.2 / 2.2), so
  // trial 1 is scored with candidate 0 (3.0); the other trials are chosen with trial 1 in, so 1.
  EXPECT_EQ(cv.choice_per_trial[0], 0u);
  EXPECT_DOUBLE_EQ(cv.cross_validated[0].errors.total_deg, 3.0);
  for (size_t t = 1; t < 4; ++t) {
    EXPECT_EQ(cv.choice_per_trial[t], 1u) << t;
  }
  const GroupMeans g = group_means(cv.cross_validated);
  EXPECT_DOUBLE_EQ(g.undisturbed.total_deg, (3.0 + 1.2) / 2.0);
  EXPECT_DOUBLE_EQ(g.disturbed.total_deg, 2.2);
  // 2 folds: trials 0, 2 in fold 0; 1, 3 in fold 1
  const CrossValidation two = cross_validate(by, 2);
  EXPECT_EQ(two.folds, 2);
  EXPECT_THROW(cross_validate(by, 5), std::invalid_argument);
  EXPECT_THROW(cross_validate(by, 1), std::invalid_argument);
  EXPECT_THROW(cross_validate({}, 0), std::invalid_argument);
  EXPECT_THROW(cross_validate({{result(1, 1.0)}, {}}, 0), std::invalid_argument);
}

TEST(CrossValidation, OverridesWrittenIntoTheBaseFileLoadBackAsParameters) {
  const std::string base = ::testing::TempDir() + "/cv_base.yaml";
  {
    std::ofstream f(base);
    f << "parallel_kf:\n  preset: default\n  sigma_mag_ut: 0.7\n";
  }
  const std::string out = ::testing::TempDir() + "/cv_out.yaml";
  write_config_with_overrides(base, {{"tilt.sigma_accel_mps2", "0.5"}, {"mag_gating", "false"}}, out, "a\nb");
  const ParallelKfParams p = load_parallel_kf_params(out);
  EXPECT_EQ(p.tilt.sigma_accel_mps2, 0.5);
  EXPECT_FALSE(p.mag_gating);
  EXPECT_EQ(p.sigma_mag_ut, 0.7);  // kept from the base
  // without a base: top-level keys, which the loader accepts as well
  write_config_with_overrides("", {{"mag_norm_tol", "0.09"}}, out);
  EXPECT_EQ(load_parallel_kf_params(out).mag_norm_tol, 0.09);
  EXPECT_THROW(write_config_with_overrides("/nonexistent/base.yaml", {}, out), std::runtime_error);
}

TEST(Resample, GivenAConstantRateWhenResampledThenEveryNewGyroSampleIsThatRateAndTheRotationIsKept) {
  // GIVEN 10 s at 2000/7 Hz of a constant 90 deg/s rotation about a skew axis, level reference
  BroadTrial t;
  t.stem = "05_synthetic";
  t.number = 5;
  t.rate_hz = 2000.0 / 7.0;
  const Eigen::Vector3d w = Eigen::Vector3d(1.0, -2.0, 0.5).normalized() * (90.0 * kRadPerDeg);
  const size_t n = 2858;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  for (size_t k = 0; k < n; ++k) {
    if (k > 0) {
      q = quat_integrate_body_rate(q, w, 1.0 / t.rate_hz);
    }
    t.gyr_rps.push_back(w);
    t.acc_mps2.push_back(Eigen::Vector3d(0.0, 0.0, 9.81));
    t.mag_ut.push_back(Eigen::Vector3d(0.0, 20.0, -40.0));
    t.opt_quat_wxyz.push_back(k == 100 ? Eigen::Vector4d::Constant(std::nan("")) : quat_to_wxyz_vec(q));
    t.movement.push_back(1);
  }
  for (const double rate : {100.0, 1000.0}) {
    // WHEN resampled
    const BroadTrial r = resample_trial(t, rate);
    // THEN the duration is kept, every gyro sample is the constant rate, and integrating them
    // reproduces the rotation at the last common instant
    const double duration = static_cast<double>(n - 1) / t.rate_hz;
    EXPECT_EQ(r.size(), static_cast<size_t>(std::floor(duration * rate + 1e-9)) + 1);
    Eigen::Quaterniond qr = Eigen::Quaterniond::Identity();
    for (size_t j = 0; j < r.size(); ++j) {
      EXPECT_LT((r.gyr_rps[j] - w).norm(), kExactRps) << j;
      if (j > 0) {
        qr = quat_integrate_body_rate(qr, r.gyr_rps[j], 1.0 / rate);
      }
    }
    const double t_last = static_cast<double>(r.size() - 1) / rate;
    const Eigen::Quaterniond q_true = quat_exp(w * t_last);
    EXPECT_LT(quat_angle_between(qr, q_true), 1e3 * kExactRad);  // sum of r.size() round-offs
    // the reference is slerped, NaN where a neighbour is NaN
    const Eigen::Quaterniond ref_last = quat_from_wxyz(r.opt_quat_wxyz.back());
    EXPECT_LT(quat_angle_between(ref_last, q_true), 1e-6);
    const double t_nan = 100.0 / t.rate_hz;
    const auto j_nan = static_cast<size_t>(std::ceil(t_nan * rate));  // first new sample after it
    EXPECT_TRUE(std::isnan(r.opt_quat_wxyz[j_nan][0]) || std::isnan(r.opt_quat_wxyz[j_nan - 1][0]));
  }
  EXPECT_THROW(resample_trial(t, 0.0), std::invalid_argument);
  EXPECT_THROW(resample_trial(t, std::nan("")), std::invalid_argument);
  EXPECT_THROW(resample_trial(BroadTrial{}, 100.0), std::invalid_argument);
}

TEST(BroadRate, GivenTheDefaultConfigurationWhenTheSameMotionIsSampledAt100HzOr1kHzThenRmseChangesByLessThan15Percent) {
  POISE_REQUIRE_SHARED_DIR(shared);
  for (const char* file : {"05_undisturbed_slow_rotation_with_breaks_B.hdf5", "32_disturbed_attached_magnet_1cm.hdf5"}) {
    const BroadTrial t = load_broad(shared + "/broad/" + file);
    auto f = make_filter("parallel_kf");
    const double native = broad_errors(run_filter(*f, t), t).total_deg;
    for (const double rate : {100.0, 1000.0}) {
      const BroadTrial r = resample_trial(t, rate);
      const double e = broad_errors(run_filter(*f, r), r).total_deg;
      std::printf("%s: %.1f Hz %.3f deg, %.0f Hz %.3f deg\n", file, t.rate_hz, native, rate, e);
      EXPECT_LT(std::abs(e - native), kRateChangeTol * native)
          << file << " at " << rate << " Hz";
    }
  }
}

TEST(Decimate, GivenATrialWhenEveryThirdSampleIsKeptThenTheRowsAreThoseSamplesAndTheRateAThird) {
  BroadTrial t;
  t.stem = "t";
  t.rate_hz = 300.0;
  for (int k = 0; k < 10; ++k) {
    t.gyr_rps.emplace_back(k, 0, 0);
    t.acc_mps2.emplace_back(0, k, 0);
    t.mag_ut.emplace_back(0, 0, k);
    t.opt_quat_wxyz.push_back(Eigen::Vector4d(1, 0, 0, 0));
    t.movement.push_back(static_cast<uint8_t>(k % 2));
  }
  const BroadTrial d = decimate_trial(t, 3);
  ASSERT_EQ(d.size(), 4u);  // 0, 3, 6, 9
  EXPECT_DOUBLE_EQ(d.rate_hz, 100.0);
  for (size_t j = 0; j < d.size(); ++j) {
    EXPECT_EQ(d.gyr_rps[j].x(), static_cast<double>(3 * j));
    EXPECT_EQ(d.acc_mps2[j].y(), static_cast<double>(3 * j));
    EXPECT_EQ(d.mag_ut[j].z(), static_cast<double>(3 * j));
    EXPECT_EQ(d.movement[j], static_cast<uint8_t>((3 * j) % 2));
  }
  EXPECT_EQ(d.opt_quat_wxyz.size(), 4u);
  EXPECT_THROW(decimate_trial(t, 0), std::invalid_argument);
  EXPECT_THROW(decimate_trial(t, 6), std::invalid_argument);  // one sample left
}

TEST(AttachMagnet, GivenATrialWhenAMagnetIsAttachedThenEveryRowFromItsTimeOnCarriesTheOffsetAndNoneBefore) {
  BroadTrial t;
  t.stem = "t";
  t.number = 11;
  t.rate_hz = 10.0;
  for (int k = 0; k < 20; ++k) {
    t.gyr_rps.emplace_back(k, 0, 0);
    t.acc_mps2.emplace_back(0, k, 0);
    t.mag_ut.emplace_back(1.0 * k, 2.0, 3.0);
    t.opt_quat_wxyz.push_back(Eigen::Vector4d(1, 0, 0, 0));
    t.movement.push_back(1);
  }
  const Eigen::Vector3d b(4.0, -5.0, 6.0);
  const BroadTrial a = attach_magnet(t, b, 1.2);  // from row 12 (t = 1.2 s) on
  ASSERT_EQ(a.size(), t.size());
  for (size_t k = 0; k < t.size(); ++k) {
    const Eigen::Vector3d expected = k >= 12 ? Eigen::Vector3d(t.mag_ut[k] + b) : t.mag_ut[k];
    EXPECT_EQ(a.mag_ut[k], expected) << "row " << k;
    EXPECT_EQ(a.gyr_rps[k], t.gyr_rps[k]);
    EXPECT_EQ(a.acc_mps2[k], t.acc_mps2[k]);
  }
  EXPECT_THROW(attach_magnet(t, Eigen::Vector3d(std::nan(""), 0, 0), 1.0), std::invalid_argument);
  EXPECT_THROW(attach_magnet(t, b, std::numeric_limits<double>::infinity()), std::invalid_argument);
  // the offset for a trial: the magnitude asked for, the same direction on every call, another one
  // for another trial
  const Eigen::Vector3d o11 = attached_magnet_offset(11, 10.0);
  EXPECT_NEAR(o11.norm(), 10.0, 1e-12);
  EXPECT_EQ(o11, attached_magnet_offset(11, 10.0));
  EXPECT_GT((o11 - attached_magnet_offset(14, 10.0)).norm(), 1e-6);
  EXPECT_NEAR(attached_magnet_offset(14, 20.0).norm(), 20.0, 1e-12);
}

/// The 19 BROAD files of the shared directory.
std::vector<std::string> shared_broad_files(const std::string& shared) {
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(shared + "/broad")) {
    if (e.path().extension() == ".hdf5") {
      files.push_back(e.path().string());
    }
  }
  return files;
}

/// The default parallel KF with BROAD's IMU delay on `files`, every `every`-th sample (1: all).
GroupMeans default_means(const std::vector<std::string>& files, size_t every, double* rate_hz = nullptr) {
  std::vector<TrialResult> rs;
  auto f = make_filter_for_broad("parallel_kf");  // the defaults + BROAD's IMU delay (its sensor)
  for (const auto& path : files) {
    const BroadTrial t = every == 1 ? load_broad(path) : decimate_trial(load_broad(path), every);
    if (rate_hz != nullptr) {
      *rate_hz = t.rate_hz;
    }
    TrialResult r;
    r.stem = t.stem;
    r.number = t.number;
    r.disturbed = t.disturbed();
    r.errors = broad_errors(run_filter(*f, t), t);
    rs.push_back(r);
  }
  return group_means(rs);
}

// Issue 32: beside the 100 Hz / 1 kHz test above, the rates a user's sensor gives when only every
// 3rd or 7th sample of BROAD's 285.7 Hz is kept (95.2 and 40.8 Hz; nothing per sample changes in
// the filter). Oracle: VQF on the same decimated trials (kVqf95*, kVqf41*).
TEST(BroadRate, GivenTheNineteenTrialsAtEveryThirdOrSeventhSampleWhenTheDefaultRunsThenItsMeansBeatVqfAtThatRate) {
  POISE_REQUIRE_SHARED_DIR(shared);
  const std::vector<std::string> files = shared_broad_files(shared);
  ASSERT_EQ(files.size(), 19u);
  struct Rate {
    size_t every;
    double vqf_undisturbed_deg, vqf_disturbed_deg;
  };
  for (const Rate& rate : {Rate{3, kVqf95UndisturbedDeg, kVqf95DisturbedDeg}, Rate{7, kVqf41UndisturbedDeg, kVqf41DisturbedDeg}}) {
    double rate_hz = 0;
    const GroupMeans g = default_means(files, rate.every, &rate_hz);
    std::printf("parallel_kf default, one sample in %zu (%.1f Hz): undisturbed %.3f (incl %.3f), disturbed %.3f "
                "(incl %.3f) deg; VQF %.2f / %.2f\n",
                rate.every, rate_hz, g.undisturbed.total_deg, g.undisturbed.inclination_deg, g.disturbed.total_deg,
                g.disturbed.inclination_deg, rate.vqf_undisturbed_deg, rate.vqf_disturbed_deg);
    EXPECT_LT(g.undisturbed.total_deg, rate.vqf_undisturbed_deg) << "every " << rate.every;
    EXPECT_LT(g.disturbed.total_deg, rate.vqf_disturbed_deg) << "every " << rate.every;
  }
}

TEST(BroadGolden, GivenTheNineteenSharedTrialsWhenTheDefaultParallelKfRunsThenItsMeansAndItsInclinationBeatVqf) {
  POISE_REQUIRE_SHARED_DIR(shared);
  const std::vector<std::string> files = shared_broad_files(shared);
  ASSERT_EQ(files.size(), 19u);
  const GroupMeans g = default_means(files, 1);
  std::printf("parallel_kf default: undisturbed %.3f (incl %.3f), disturbed %.3f (incl %.3f) deg\n",
              g.undisturbed.total_deg, g.undisturbed.inclination_deg, g.disturbed.total_deg,
              g.disturbed.inclination_deg);
  EXPECT_LT(g.undisturbed.total_deg, kVqfUndisturbedDeg);
  EXPECT_LT(g.disturbed.total_deg, kVqfDisturbedDeg);
  EXPECT_LT(g.undisturbed.inclination_deg, kVqfInclUndisturbedDeg);
  EXPECT_LT(g.disturbed.inclination_deg, kVqfInclDisturbedDeg);
}

TEST(EvalCli, GivenAGridWhenEvaluatedWithFoldsThenInSampleAndCrossValidatedMeansArePrintedAndTuneWritesTheChoice) {
  POISE_REQUIRE_SHARED_DIR(shared);
  const std::string a = shared + "/broad/05_undisturbed_slow_rotation_with_breaks_B.hdf5";
  const std::string b = shared + "/broad/14_undisturbed_slow_translation_with_breaks_B.hdf5";
  const std::string dir = ::testing::TempDir() + "/cv_cli";
  const std::string base = std::string(POISE_SOURCE_DIR) + "/config/filters/parallel_kf_broad.yaml";
  const auto r = testing::run({testing::bin("poise"), "eval", "broad", "--config", base, "--out-dir", dir, "--grid",
                               "mag_norm_tol=0.05,0.1", "--folds", "2", a, b},
                              std::chrono::seconds(120));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("in-sample "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("cross-validated "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("2-fold"), std::string::npos) << r.output;
  const std::string chosen = dir + "/chosen.yaml";
  const auto t = testing::run({testing::bin("poise"), "tune", "--out-dir", dir, "-o", chosen, "--grid",
                               "mag_norm_tol=0.05,0.1", a, b},
                              std::chrono::seconds(120));
  EXPECT_EQ(t.exit_code, 0) << t.output;
  const ParallelKfParams p = load_parallel_kf_params(chosen);
  EXPECT_TRUE(p.mag_norm_tol == 0.05 || p.mag_norm_tol == 0.1) << p.mag_norm_tol;
  const auto bad = testing::run({testing::bin("poise"), "eval", "broad", "--out-dir", dir, "--grid", "nokey", a},
                                std::chrono::seconds(30));
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("nokey"), std::string::npos) << bad.output;
  // a filter whose BROAD figures use their own configuration needs it as the grid's base
  const auto no_base = testing::run({testing::bin("poise"), "eval", "broad", "--filter", "selective", "--out-dir", dir,
                                     "--grid", "heading_norm_tolerance=0.05,0.1", a},
                                    std::chrono::seconds(30));
  EXPECT_EQ(no_base.exit_code, 1) << no_base.output;
  EXPECT_NE(no_base.output.find("--config"), std::string::npos) << no_base.output;
}

}  // namespace
}  // namespace poise::eval
