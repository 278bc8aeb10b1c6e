// Calibration from a live stream (pure): gyro bias from a still period, magnetometer hard/soft
// iron from an ellipsoid fit over a rotation sequence.
//
// Ellipsoid model: raw m = A h + b, h the true field (|h| = B), A the soft-iron distortion, b the
// hard-iron offset. The fit finds the quadric (m - c)^T E (m - c) = 1 by linear least squares on
//   a x^2 + b y^2 + c z^2 + 2f yz + 2g xz + 2h xy + 2p x + 2q y + 2r z = 1
// (points centred and scaled first for conditioning), then c = -M^-1 n and E = M / (1 + c^T M c).
// The correction is W = B E^(1/2) (symmetric square root), so |W (m - c)| = B: the symmetric
// (rotation-free) inverse of A up to scale. B defaults to the geometric mean of the radii.
#pragma once

#include <array>
#include <cstddef>
#include <deque>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "poise/imu/protocol.h"

namespace poise::imu {

struct EllipsoidFit {
  bool ok = false;
  std::string error;                        ///< why not ok (what to do)
  Eigen::Vector3d hard_iron_ut{0, 0, 0};    ///< c
  Eigen::Matrix3d soft_iron = Eigen::Matrix3d::Identity();  ///< W
  Eigen::Vector3d radii_ut{0, 0, 0};        ///< ellipsoid semi-axes, uT (ascending)
  double field_ut = 0;                      ///< B: |corrected field|
  double residual_rms_ut = 0;               ///< rms(|W (m - c)| - B)
  double spread_before_ut = 0;              ///< rms(|m - mean| - mean|m - mean|) before correction
  std::size_t points = 0;
};

/// Fits an ellipsoid to >= 9 points (use >= 100 spread over the sphere). `field_ut` > 0 forces B.
EllipsoidFit fit_ellipsoid(const std::vector<Eigen::Vector3d>& points, double field_ut = 0.0);

/// Fraction of direction bins (Fibonacci sphere) hit by unit vectors.
class SphereCoverage {
 public:
  explicit SphereCoverage(int bins = 60);
  void clear();
  void add(const Eigen::Vector3d& direction);
  [[nodiscard]] double fraction() const;

 private:
  std::vector<Eigen::Vector3d> centers_;
  std::vector<bool> hit_;
  int hits_ = 0;
};

struct CalibrationParams {
  double still_s = 5.0;                ///< still period needed for the gyro bias, s
  double gyro_still_std_rps = 0.01;    ///< max gyro std (any axis) to count as still, rad/s
  double accel_still_std_mps2 = 0.08;  ///< max accel-norm std to count as still, m/s^2
  double coverage_target = 0.75;       ///< fraction of direction bins needed to finish rotating
  std::size_t min_mag_points = 150;
  double min_mag_spacing_ut = 1.0;     ///< ignore samples closer than this to the last kept one
  std::size_t max_mag_points = 20000;
};

/// Guided two-phase session. Feed every raw sample (sensor axes, uncalibrated) with its sensor
/// time; read progress() for the display; when done(), result() has the calibration.
class CalibrationSession {
 public:
  enum class Phase { kStill, kRotate, kDone };
  explicit CalibrationSession(const CalibrationParams& p = {});
  void add(const RawSample& s, int64_t sensor_ns);
  /// Skips the still phase (keeps the current gyro bias).
  void skip_still();
  /// Ends the rotation phase now (e.g. timeout) and fits with what was collected.
  void finish();

  struct Progress {
    Phase phase = Phase::kStill;
    double still_fraction = 0;   ///< of still_s held so far
    bool moving = false;         ///< the last window was not still
    double coverage = 0;         ///< of coverage_target's bins
    std::size_t mag_points = 0;
    double residual_ut = 0;      ///< of a provisional fit (0 until there are enough points)
  };
  [[nodiscard]] Progress progress() const;
  [[nodiscard]] bool done() const { return phase_ == Phase::kDone; }
  [[nodiscard]] bool has_gyro_bias() const { return has_gyro_bias_; }
  [[nodiscard]] const Eigen::Vector3d& gyro_bias_rps() const { return gyro_bias_; }
  [[nodiscard]] double gyro_noise_rps() const { return gyro_noise_; }
  [[nodiscard]] const EllipsoidFit& mag_fit() const { return fit_; }
  [[nodiscard]] const std::vector<Eigen::Vector3d>& mag_points() const { return mag_; }

 private:
  void update_still(const RawSample& s, int64_t sensor_ns);
  void update_coverage();
  CalibrationParams params_;
  Phase phase_ = Phase::kStill;
  struct StillItem {
    int64_t t;
    Eigen::Vector3d gyro;
    double accel_norm;
  };
  std::deque<StillItem> still_;
  bool moving_ = false;
  bool has_gyro_bias_ = false;
  Eigen::Vector3d gyro_bias_{0, 0, 0};
  double gyro_noise_ = 0;
  std::vector<Eigen::Vector3d> mag_;
  SphereCoverage coverage_;
  double coverage_fraction_ = 0;
  std::size_t coverage_at_ = 0;
  double provisional_residual_ = 0;
  EllipsoidFit fit_;
};

}  // namespace poise::imu
