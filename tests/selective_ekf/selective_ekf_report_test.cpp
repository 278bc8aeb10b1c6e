// The selective EKF's outputs in the shared shapes: world-frame covariances and the vision input
// of a camera pose (closed-form oracles).
#include "poise/selective_ekf/selective_ekf.h"

#include <gtest/gtest.h>

#include <cmath>

namespace poise {
namespace {

constexpr double kExact = 1e-12;  // pure reordering / rotation of given numbers

// Identity attitude: [p v theta] is the [t v theta] block reorder of the estimate's error covariance P_err.
TEST(SelectiveEkfReport, PoseCovarianceReordersBlocksAtIdentityAttitude) {
  SelectiveEkfState x;
  for (int i = 0; i < SelectiveEkf::kN; ++i) {
    for (int j = 0; j < SelectiveEkf::kN; ++j) {
      x.P_err(i, j) = 100.0 * i + j;  // every entry names its row and column
    }
  }
  const Eigen::Matrix<double, 9, 9> c = pose_covariance_world(x, Eigen::Quaterniond::Identity());
  constexpr int kT = SelectiveEkf::kT;
  constexpr int kV = SelectiveEkf::kV;
  constexpr int kTh = SelectiveEkf::kTh;
  const int from[9] = {kT, kT + 1, kT + 2, kV, kV + 1, kV + 2, kTh, kTh + 1, kTh + 2};
  for (int i = 0; i < 9; ++i) {
    for (int j = 0; j < 9; ++j) {
      EXPECT_NEAR(c(i, j), x.P_err(from[i], from[j]), kExact) << i << "," << j;
    }
  }
}

// A yaw of 90 deg maps a body-x attitude variance onto world y; position is not rotated.
TEST(SelectiveEkfReport, PoseCovarianceRotatesAttitudeErrorIntoTheWorld) {
  SelectiveEkfState x;
  x.P_err.setZero();
  x.P_err(SelectiveEkf::kTh, SelectiveEkf::kTh) = 4e-4;  // body x, rad^2
  x.P_err(SelectiveEkf::kT, SelectiveEkf::kT) = 1e-2;    // world x position, m^2
  const Eigen::Quaterniond yaw90(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()));
  const Eigen::Matrix<double, 9, 9> c = pose_covariance_world(x, yaw90);
  EXPECT_NEAR(c(6, 6), 0.0, kExact);
  EXPECT_NEAR(c(7, 7), 4e-4, kExact);
  EXPECT_NEAR(c(0, 0), 1e-2, kExact);
}

TEST(SelectiveEkfReport, VisionInputTakesMeanStdAndNanWhenUnusable) {
  CameraPoseMeasurement m;
  m.stamp_ns = 123;
  m.p_world_camera_m = Eigen::Vector3d(1, 2, 3);
  m.covariance.setZero();
  m.covariance.diagonal() << 1e-4, 2e-4, 3e-4, 4e-6, 4e-6, 4e-6;
  VisionPose v = to_vision_pose(m);
  EXPECT_EQ(v.capture_stamp_ns, 123);
  EXPECT_EQ(v.p_world_camera_m, Eigen::Vector3d(1, 2, 3));
  EXPECT_NEAR(v.sigma_m, std::sqrt(2e-4), kExact);
  EXPECT_NEAR(v.sigma_rad, 2e-3, kExact);
  m.covariance(0, 0) = std::nan("");
  m.covariance.diagonal().tail<3>().setZero();
  v = to_vision_pose(m);
  EXPECT_TRUE(std::isnan(v.sigma_m)) << "NaN covariance: the filter's default applies";
  EXPECT_TRUE(std::isnan(v.sigma_rad)) << "zero covariance: the filter's default applies";
}

TEST(SelectiveEkfReport, BeforeAnySampleEverySourceIsNotAvailable) {
  const SelectiveEkf ekf;
  const SourceReports r = selective_ekf_sources(ekf);
  ASSERT_EQ(r.size(), 8U);  // gyro, imu_quat, mag, vision x2, accel_tilt, mag_heading, zero_rate
  for (const SourceReport& s : r) {
    EXPECT_EQ(s.decision, SourceDecision::kNotAvailable) << to_string(s.source);
  }
}

}  // namespace
}  // namespace poise
