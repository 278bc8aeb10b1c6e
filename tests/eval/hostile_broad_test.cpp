// Hostile BROAD-layout files (issue 19, item 8): a rate that is not a rate, reference rows that
// are not rotations, trials without a scorable sample. Small HDF5 files written here.
#include "poise/eval/broad.h"
#include "poise/eval/runner.h"

#include "poise/core/attitude.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

namespace poise::eval {
namespace {

struct SmallTrial {
  double rate_hz = 100.0;
  size_t n = 200;
  std::vector<Eigen::Vector4d> quat;  // default: identity rows
  std::vector<uint8_t> movement;      // default: all 1
  bool nan_imu = false;               // every IMU sample NaN: a filter rejects them all
};

void write_dataset(hid_t file, const char* name, hid_t type, size_t rows, size_t cols, const void* data) {
  const hsize_t dims[2] = {rows, cols};
  const hid_t space = H5Screate_simple(cols == 1 ? 1 : 2, dims, nullptr);
  const hid_t ds = H5Dcreate2(file, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(ds, 0) << name;
  ASSERT_GE(H5Dwrite(ds, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), 0) << name;
  H5Dclose(ds);
  H5Sclose(space);
}

/// A BROAD-layout file: the sensor at rest, level, the reference `t.quat`.
std::string write_trial(const std::string& stem, const SmallTrial& t) {
  const std::string path = ::testing::TempDir() + "/" + stem + ".hdf5";
  const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  EXPECT_GE(file, 0) << path;
  std::vector<double> gyr(3 * t.n, 0.0), acc(3 * t.n, 0.0), mag(3 * t.n, 0.0), quat(4 * t.n, 0.0);
  for (size_t k = 0; k < t.n; ++k) {
    acc[3 * k + 2] = 9.81;
    mag[3 * k + 1] = 20.0;
    mag[3 * k + 2] = -40.0;
    if (t.nan_imu) {
      for (int c = 0; c < 3; ++c) {
        gyr[3 * k + static_cast<size_t>(c)] = std::nan("");
        acc[3 * k + static_cast<size_t>(c)] = std::nan("");
        mag[3 * k + static_cast<size_t>(c)] = std::nan("");
      }
    }
    const Eigen::Vector4d q = k < t.quat.size() ? t.quat[k] : Eigen::Vector4d(1, 0, 0, 0);
    for (int c = 0; c < 4; ++c) {
      quat[4 * k + static_cast<size_t>(c)] = q[c];
    }
  }
  std::vector<uint8_t> movement = t.movement.empty() ? std::vector<uint8_t>(t.n, 1) : t.movement;
  write_dataset(file, "imu_gyr", H5T_NATIVE_DOUBLE, t.n, 3, gyr.data());
  write_dataset(file, "imu_acc", H5T_NATIVE_DOUBLE, t.n, 3, acc.data());
  write_dataset(file, "imu_mag", H5T_NATIVE_DOUBLE, t.n, 3, mag.data());
  write_dataset(file, "opt_quat", H5T_NATIVE_DOUBLE, t.n, 4, quat.data());
  write_dataset(file, "movement", H5T_NATIVE_UINT8, t.n, 1, movement.data());
  const hid_t aspace = H5Screate(H5S_SCALAR);
  const hid_t attr = H5Acreate2(file, "sampling_rate", H5T_NATIVE_DOUBLE, aspace, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(attr, H5T_NATIVE_DOUBLE, &t.rate_hz);
  H5Aclose(attr);
  H5Sclose(aspace);
  H5Fclose(file);
  return path;
}

TEST(HostileBroad, GivenASamplingRateThatIsNotARateWhenLoadedThenTheErrorNamesTheFileAndTheAttribute) {
  const double inf = std::numeric_limits<double>::infinity();
  for (const double rate : {1e300, 0.0, -100.0, std::nan(""), inf, 1e-300, 0.5, 2e6}) {
    SmallTrial t;
    t.rate_hz = rate;
    const std::string path = write_trial("bad_rate", t);
    try {
      (void)load_broad(path);
      ADD_FAILURE() << "sampling_rate " << rate << " accepted";
    } catch (const std::runtime_error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(path), std::string::npos) << msg;
      EXPECT_NE(msg.find("sampling_rate"), std::string::npos) << msg;
    }
  }
  for (const double rate : {kBroadMinRateHz, 285.714, kBroadMaxRateHz}) {  // the bounds themselves load
    SmallTrial t;
    t.rate_hz = rate;
    EXPECT_EQ(load_broad(write_trial("good_rate", t)).rate_hz, rate);
  }
}

TEST(HostileBroad, GivenReferenceRowsThatAreNotRotationsWhenScoredThenTheyAreCountedAndNeverScored) {
  SmallTrial t;
  t.n = 10;
  t.quat.assign(t.n, Eigen::Vector4d(1, 0, 0, 0));
  t.quat[2] = Eigen::Vector4d::Zero();           // all-zero row
  t.quat[5] = Eigen::Vector4d(2, 0, 0, 0);       // norm 2
  t.quat[7] = Eigen::Vector4d(1e-30, 0, 0, 0);   // nearly zero
  const BroadTrial trial = load_broad(write_trial("zero_quat", t));
  EXPECT_EQ(trial.invalid_reference_rows, 3u);
  // estimates: a 3 deg yaw error everywhere -> RMS 3 deg over the 7 valid rows, finite
  const std::vector<Eigen::Quaterniond> est(t.n, quat_from_euler_zyx(0, 0, 3 * kRadPerDeg));
  const TrialErrors e = broad_errors(est, trial);
  EXPECT_EQ(e.samples, 7u);
  EXPECT_NEAR(e.total_deg, 3.0, 1e-9);
  EXPECT_TRUE(std::isfinite(e.heading_deg) && std::isfinite(e.inclination_deg));
}

TEST(HostileBroad, GivenANonFiniteEstimateWhenScoredThenItCountsAsTheLargestErrorNeverAsNaN) {
  SmallTrial t;
  t.n = 4;
  const BroadTrial trial = load_broad(write_trial("nan_estimate", t));
  std::vector<Eigen::Quaterniond> est(t.n, Eigen::Quaterniond::Identity());
  est[1] = Eigen::Quaterniond(std::nan(""), 0, 0, 0);
  est[2] = Eigen::Quaterniond(0, 0, 0, 0);
  const TrialErrors e = broad_errors(est, trial);
  EXPECT_EQ(e.nonfinite_estimates, 2u);
  // oracle: RMS of {0, 180, 180, 0} deg = 180 / sqrt(2)
  EXPECT_NEAR(e.total_deg, 180.0 / std::sqrt(2.0), 1e-9);
}

TEST(HostileBroad, GivenATrialWithoutScorableSamplesWhenAveragedThenItIsExcludedAndNamedNeverCountedAsZero) {
  std::vector<TrialResult> rs(3);
  rs[0].stem = "01_a";
  rs[0].errors.total_deg = 2.0;
  rs[0].errors.samples = 10;
  rs[1].stem = "02_empty";  // samples 0
  rs[2].stem = "03_b";
  rs[2].errors.total_deg = 4.0;
  rs[2].errors.samples = 10;
  const GroupMeans g = group_means(rs);
  EXPECT_EQ(g.n_undisturbed, 2);
  EXPECT_DOUBLE_EQ(g.undisturbed.total_deg, 3.0);  // (2 + 4) / 2, not (2 + 0 + 4) / 3
  ASSERT_EQ(g.unscored.size(), 1u);
  EXPECT_EQ(g.unscored.front(), "02_empty");
  std::ostringstream os;
  print_table(os, "x", rs);
  EXPECT_NE(os.str().find("excluded from the means: 1 trial(s) without scorable samples: 02_empty"),
            std::string::npos)
      << os.str();
  EXPECT_NE(os.str().find("no scorable samples (movement with a valid reference): excluded"), std::string::npos)
      << os.str();
}

TEST(HostileBroad, GivenTrialsWithoutScorableSamplesWhenEvaluatedThenTheyAreExcludedAndOnlyNoneAtAllIsAnError) {
  SmallTrial still;
  still.movement.assign(still.n, 0);  // nothing scored: no movement phase
  const std::string empty = write_trial("02_no_movement", still);
  SmallTrial ok;
  const std::string good = write_trial("01_level_rest", ok);
  const std::string dir = ::testing::TempDir() + "/hostile_eval";
  const auto both = testing::run({testing::bin("poise"), "eval", "broad", "--out-dir", dir, good, empty},
                                 std::chrono::seconds(60));
  EXPECT_EQ(both.exit_code, 0) << both.output;
  EXPECT_NE(both.output.find("mean all (1 trials)"), std::string::npos) << both.output;
  EXPECT_NE(both.output.find("excluded from the means: 1 trial(s) without scorable samples: 02_no_movement"),
            std::string::npos)
      << both.output;
  const auto none = testing::run({testing::bin("poise"), "eval", "broad", "--out-dir", dir, empty},
                                 std::chrono::seconds(60));
  EXPECT_NE(none.exit_code, 0) << none.output;
  EXPECT_NE(none.output.find("no trial has scorable samples"), std::string::npos) << none.output;
  // Issue 33: every sample rejected by the filter (NaN IMU): the identities it leaves are no
  // estimate; the trial is excluded and named, never scored as the initial quaternion's error.
  SmallTrial rejected;
  rejected.nan_imu = true;
  const std::string nan = write_trial("04_all_rejected", rejected);
  const auto rej = testing::run({testing::bin("poise"), "eval", "broad", "--out-dir", dir, good, nan},
                                std::chrono::seconds(60));
  EXPECT_EQ(rej.exit_code, 0) << rej.output;
  EXPECT_NE(rej.output.find("04_all_rejected: the filter rejected every sample (no estimate): excluded"),
            std::string::npos)
      << rej.output;
  EXPECT_NE(rej.output.find("mean all (1 trials)"), std::string::npos) << rej.output;
  EXPECT_NE(rej.output.find("excluded from the means: 1 trial(s) without scorable samples: 04_all_rejected"),
            std::string::npos)
      << rej.output;
  // tune leaves it out of its choice too, and with nothing else to choose from refuses.
  const auto tune = testing::run({testing::bin("poise"), "tune", "--grid", "mag_norm_tol=0.05,0.1", "--out-dir",
                                  dir + "/tune", "-o", dir + "/chosen.yaml", good, nan},
                                 std::chrono::seconds(120));
  EXPECT_EQ(tune.exit_code, 0) << tune.output;
  EXPECT_NE(tune.output.find("04_all_rejected: the filter rejected every sample (no estimate): excluded"),
            std::string::npos)
      << tune.output;
  EXPECT_NE(tune.output.find("1 without scorable samples excluded"), std::string::npos) << tune.output;
  const auto tune_none = testing::run({testing::bin("poise"), "tune", "--grid", "mag_norm_tol=0.05,0.1",
                                       "--out-dir", dir + "/tune", "-o", dir + "/chosen.yaml", nan},
                                      std::chrono::seconds(120));
  EXPECT_NE(tune_none.exit_code, 0) << tune_none.output;
  EXPECT_NE(tune_none.output.find("no trial has scorable samples"), std::string::npos) << tune_none.output;
  SmallTrial fast;
  fast.rate_hz = 1e300;
  const std::string bad = write_trial("03_bad_rate", fast);
  const auto rate = testing::run({testing::bin("poise"), "eval", "broad", "--out-dir", dir, bad},
                                 std::chrono::seconds(60));
  EXPECT_NE(rate.exit_code, 0) << rate.output;
  EXPECT_NE(rate.output.find(bad + ": attribute 'sampling_rate' = 1e+300 Hz"), std::string::npos) << rate.output;
}

// Issue 33: a write the device refuses (/dev/full: every write fails with ENOSPC) is an error
// exit naming the file, never "wrote" and exit 0 over a 0-byte file.
TEST(HostileBroad, GivenAFullDeviceAsOutputWhenTuneAndEvalWriteThenTheyFailNamingTheFile) {
  SmallTrial ok;
  const std::string a = write_trial("01_full_a", ok);
  const std::string b = write_trial("02_full_b", ok);
  const std::string dir = ::testing::TempDir() + "/hostile_full";
  const auto tune = testing::run({testing::bin("poise"), "tune", "--grid", "mag_norm_tol=0.05,0.1", "--out-dir", dir,
                                  "-o", "/dev/full", a, b},
                                 std::chrono::seconds(120));
  EXPECT_NE(tune.exit_code, 0) << tune.output;
  EXPECT_EQ(tune.output.find("wrote /dev/full"), std::string::npos) << tune.output;
  EXPECT_NE(tune.output.find("error while writing '/dev/full'"), std::string::npos) << tune.output;
  // The direct check of the writer: the same refusal as an exception naming the file.
  try {
    write_quaternion_csv("/dev/full", {Eigen::Quaterniond::Identity()}, 100.0);
    ADD_FAILURE() << "no error writing /dev/full";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("'/dev/full'"), std::string::npos) << e.what();
  }
}

// GIVEN only undisturbed trials WHEN the table is printed THEN the disturbed mean over 0 trials is
// "-", never 0.000 or nan, and the scored-samples column says what it counts.
TEST(EvalTable, GivenNoDisturbedTrialWhenPrintedThenItsMeanIsADashNeverZeroOrNan) {
  TrialResult a;
  a.stem = "01_undisturbed_slow_rotation_A";
  a.number = 1;
  a.errors.total_deg = 1.5;
  a.errors.heading_deg = 1.2;
  a.errors.inclination_deg = 0.5;
  a.errors.samples = 1000;
  std::ostringstream os;
  print_table(os, "parallel_kf", {a});
  const std::string out = os.str();
  std::istringstream lines(out);
  std::string line;
  bool seen = false;
  while (std::getline(lines, line)) {
    if (line.rfind("mean disturbed", 0) == 0) {
      seen = true;
      EXPECT_EQ(line.find("0.000"), std::string::npos) << line;
      EXPECT_NE(line.find("(0 trials)"), std::string::npos) << line;
      EXPECT_NE(line.find(" -"), std::string::npos) << line;
    }
  }
  EXPECT_TRUE(seen) << out;
  EXPECT_EQ(out.find("nan"), std::string::npos) << out;
  EXPECT_NE(out.find("scored: the samples the RMSE is over"), std::string::npos) << out;
  EXPECT_EQ(format_mean_figure(std::nan(""), 3, 6), "     -");
}

}  // namespace
}  // namespace poise::eval
