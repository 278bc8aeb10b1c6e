// BROAD benchmark support: HDF5 reader, the benchmark's error metric, group means.
// Dataset: D. Laidig, M. Caruso, A. Cereatti, T. Seel, "BROAD - A Benchmark for Robust Inertial
// Orientation Estimation", Data 6(7):72, 2021 (CC BY 4.0). Layout and metric: shared/broad/README.md.
#pragma once

#include "poise/core/types.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <string>
#include <vector>

namespace poise::eval {

/// Sampling rates a trial may declare (attribute sampling_rate), Hz: a sample interval between
/// 1 us and 1 s. Outside it the nanosecond stamps k * 1e9 / rate lose their resolution or the
/// filters' rate-based time constants mean nothing; load_broad() refuses such a file.
constexpr double kBroadMinRateHz = 1.0;
constexpr double kBroadMaxRateHz = 1e6;
/// A reference quaternion row counts as valid when its norm is within this of 1 (optical
/// references are stored unit-norm to float precision); other finite rows (e.g. all zeros) are
/// not a rotation: load_broad() marks them lost (NaN) and counts them.
constexpr double kReferenceNormTol = 1e-3;
/// BROAD's IMU lags its optical reference by this much (its internal filter): the median of
/// `poise calibrate imu-delay` over the undisturbed trials 01-18 (4.06-4.45 ms). A property of the
/// dataset's sensor, like a calibration file: `poise eval broad` gives it to the filters that take
/// an imu_delay_s (parallel_kf, selective) unless a --config is given;
/// config/filters/{parallel_kf,selective_ekf}_broad.yaml hold the same value (tests keep them equal).
inline constexpr double kBroadImuDelayS = 0.00418;

/// One BROAD trial in memory. Sample k is at t = k / rate_hz.
struct BroadTrial {
  std::string path;
  std::string stem;          ///< file name without directory and extension
  int number = 0;            ///< leading trial number (01..39), 0 if none
  double rate_hz = 0.0;      ///< attribute sampling_rate
  std::vector<Eigen::Vector3d> gyr_rps;
  std::vector<Eigen::Vector3d> acc_mps2;
  std::vector<Eigen::Vector3d> mag_ut;
  std::vector<Eigen::Vector4d> opt_quat_wxyz;  ///< reference q_world_body [w,x,y,z]; NaN rows = lost
  /// Finite reference rows that were not unit quaternions (|norm - 1| > kReferenceNormTol), marked
  /// lost (NaN) by load_broad(); reported by `poise eval broad`.
  size_t invalid_reference_rows = 0;
  std::vector<uint8_t> movement;               ///< 1 while the motion phase runs
  /// Reference position of the optical body, m (dataset opt_pos); NaN rows = lost; empty when the
  /// file has none. Used to synthesise vision poses (selective EKF hybrid benchmark).
  std::vector<Eigen::Vector3d> opt_pos_m;
  [[nodiscard]] size_t size() const { return gyr_rps.size(); }
  /// Sample k as an ImuSample (stamp = round(k * 1e9 / rate)).
  [[nodiscard]] ImuSample sample(size_t k) const;
  /// Trials 1-23 are undisturbed, 24-39 disturbed.
  [[nodiscard]] bool disturbed() const { return number >= 24; }
};

/// Reads a BROAD HDF5 file (datasets imu_gyr, imu_acc, imu_mag, opt_quat, movement; attribute
/// sampling_rate). Accepts N x k and k x N storage. Throws std::runtime_error with the file and
/// dataset or attribute name on any problem (a sampling_rate outside [kBroadMinRateHz,
/// kBroadMaxRateHz] or not finite included). Reference rows that are finite but not unit
/// quaternions are marked lost and counted (invalid_reference_rows).
BroadTrial load_broad(const std::string& path);

/// Throws std::runtime_error "<what> = <rate> Hz is not a sampling rate (...)" unless rate_hz is
/// in [kBroadMinRateHz, kBroadMaxRateHz].
void check_rate(double rate_hz, const std::string& what);

/// Per-trial errors (degrees), RMS over samples with movement and a finite reference.
struct TrialErrors {
  double total_deg = 0.0;
  double heading_deg = 0.0;
  double inclination_deg = 0.0;
  size_t samples = 0;  ///< samples scored; 0: the trial has no figure (excluded from means)
  /// Scored samples whose estimate was not a finite quaternion of non-zero norm: each scored as
  /// the largest error, 180 deg in total, heading and inclination (a broken filter never looks good).
  size_t nonfinite_estimates = 0;
  [[nodiscard]] bool scored() const { return samples > 0; }
};

/// The benchmark metric: q_err = q_est (x) conj(q_ref) (both normalised, world frame);
/// total = 2 acos(|w|), heading = 2 atan(|z / w|), inclination = 2 acos(sqrt(w^2 + z^2)).
/// `estimates` holds one q_world_body per sample. Throws std::invalid_argument on size mismatch.
TrialErrors broad_errors(const std::vector<Eigen::Quaterniond>& estimates, const BroadTrial& trial);

/// Errors of one sample (degrees): {total, heading, inclination}.
Eigen::Vector3d broad_sample_errors_deg(const Eigen::Quaterniond& q_est, const Eigen::Quaterniond& q_ref);

/// The trial as an IMU sampling at `rate_hz` would have recorded it (rate independence tests):
/// the gyro is integrated at the original rate (each sample the mean rate over the preceding
/// interval) and the new gyro samples are the mean rates of that orientation over the new
/// intervals, so the rotation is the same at any rate; accelerometer, magnetometer and reference
/// position are interpolated linearly, the reference orientation by slerp (NaN where either
/// neighbour is NaN), `movement` by the nearest original sample. Throws std::invalid_argument
/// for a rate outside [kBroadMinRateHz, kBroadMaxRateHz] or a trial with fewer than 2 samples.
BroadTrial resample_trial(const BroadTrial& trial, double rate_hz);

/// Every `every`-th sample of a trial (0, every, 2 every, ...), every row kept as recorded (no
/// anti-alias filter: what a sensor read at the lower rate gives when its own filter is left as it
/// was), rate_hz / every. Throws std::invalid_argument for every == 0 or fewer than 2 samples left.
BroadTrial decimate_trial(const BroadTrial& trial, size_t every);

/// An attached magnet emulated on a recorded trial (robustness on inputs BROAD's own magnet trials
/// do not cover): from `from_s` seconds into the trial on, the constant body-frame field `offset_ut`
/// (uT) is added to every magnetometer row, as a small permanent magnet fixed to the sensor adds
/// (a hard-iron offset that turns with the body). Rows before `from_s` are left as recorded.
/// Throws std::invalid_argument for a non-finite offset or time.
BroadTrial attach_magnet(const BroadTrial& trial, const Eigen::Vector3d& offset_ut, double from_s);

/// The offset attach_magnet() is given for trial `number` by `poise eval broad --attach-magnet-ut`:
/// magnitude `magnitude_ut` along a direction drawn uniformly on the sphere from the trial's number
/// (the same direction on every run, a different one per trial).
Eigen::Vector3d attached_magnet_offset(int number, double magnitude_ut);

/// Leading integer of a file stem ("24_disturbed_tapping_A" -> 24), 0 if none.
int trial_number_from_stem(const std::string& stem);

}  // namespace poise::eval
