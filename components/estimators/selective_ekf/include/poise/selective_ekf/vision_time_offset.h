// The camera-IMU time offset estimated online (issue 36), beside the selective EKF.
//
// Convention (Kalibr's timeshift_cam_imu, the selective EKF's vision_time_offset_s): a frame
// stamped s shows the pose at the filter's (IMU) time s + offset. A camera that stamps its frames
// X s after the exposure has offset = -X.
//
// Model: one scalar state, the offset d (s), a random walk (walk_s_sqrt_s, s/sqrt(s): how fast it
// may change), prior N(prior_s, prior_sigma_s^2). Measurement per camera frame k, paired with the
// newest earlier frame a at least baseline_s before it (each frame is an end of about two pairs):
//   V   = q_a^-1 (x) q_k                 the camera's body rotation between the two frames
//   G(d) = gyro (bias removed, rate linearly interpolated between samples) integrated from
//          s_a + d to s_k + d             the same rotation from the IMU, at the shifted times
//   r(d) = log(G(d)^-1 (x) V) = J (d_true - d) + n,  J = -dr/dd (central difference, 1 ms)
// J is the change of the body rate over the pair (a rotation at a constant rate is the same
// rotation whatever the shift): observable whenever the head's rotation changes, which head
// motion does all the time. n: both frames' attitude noise (doubled: each frame is in two pairs)
// plus the gyro's white noise over the pair. A scalar Kalman update over the three rows, gated
// (NIS above gate_sigma^2 rejected); |J| below min_rate_change_rps skips the pair (no
// information). The bias removed from the gyro is the filter's estimate: its error covariance
// (add_gyro) enters each pair's rows as T^2 P_bb (T the pair's length), so a bias not yet learnt
// (a cold start) cannot pull the offset while claiming a small sigma. The filter's attitude never
// feeds back: the estimate uses only the gyro (less the filter's bias) and the camera, so a filter
// pulled off by mis-timed frames cannot bias it.
// No clocks, no logging: the stamps are the only time.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <deque>

namespace poise {

struct VisionTimeOffsetParams {
  double prior_s = 0.0;            ///< the offset before any frame, s
  double prior_sigma_s = 0.0;      ///< its 1-sigma, s; 0 = not estimated (the prior is exact)
  double walk_s_sqrt_s = 1.0e-4;   ///< random walk of the offset, s/sqrt(s)
  double baseline_s = 0.3;         ///< pair frames at least this far apart, s
  double max_pair_s = 0.6;         ///< ... and at most this far (longer gaps: no pair), s
  double min_rate_change_rps = 0.05;  ///< |J| below: the pair carries no timing information
  double gate_sigma = 5.0;         ///< NIS above gate_sigma^2: the pair is rejected
  double converged_sigma_s = 0.002;   ///< converged when the estimate's sigma is below, s
  double max_abs_s = 0.2;          ///< the estimate is kept within +-this, s
  double sigma_gyro_rps = 0.01;    ///< gyro white noise per sample, rad/s
};

/// Why the last frame did or did not update the offset.
enum class TimeOffsetDecision : uint8_t {
  kNone = 0,       ///< no frame yet
  kUsed,
  kRejectedGate,   ///< the pair's innovation failed the gate
  kNoPair,         ///< no earlier frame baseline_s..max_pair_s before it (start, after a gap)
  kNoMotion,       ///< the body rate did not change over the pair (|J| small)
  kNoGyro,         ///< the gyro does not cover the pair's shifted interval (yet or any more)
  kNotEstimated,   ///< prior_sigma_s 0: the offset is the prior
  kCount
};
const char* to_string(TimeOffsetDecision d);

struct VisionTimeOffsetStatus {
  double offset_s = 0.0;
  double sigma_s = 0.0;
  bool estimating = false;      ///< prior_sigma_s > 0
  bool converged = false;       ///< sigma_s <= converged_sigma_s (an estimate with no prior is exact)
  TimeOffsetDecision last = TimeOffsetDecision::kNone;
  double innovation_rad = 0.0;  ///< |r| of the last pair
  double test_ratio = 0.0;      ///< NIS / gate_sigma^2 of the last pair
  int64_t last_used_stamp_ns = -1;  ///< camera stamp of the last pair used
  uint64_t used = 0;
  uint64_t rejected = 0;        ///< by the gate
  uint64_t by_decision[static_cast<size_t>(TimeOffsetDecision::kCount)] = {};
};

class VisionTimeOffsetEstimator {
 public:
  /// Throws std::invalid_argument when a parameter is not finite or out of its range.
  explicit VisionTimeOffsetEstimator(const VisionTimeOffsetParams& p = {});
  void reset();
  /// One gyro sample, bias removed, at the filter's time t_ns (increasing), with the removed
  /// bias's error covariance ((rad/s)^2, body frame; zero: the bias known): a bias error db turns
  /// the gyro's rotation over a pair of length T by about db T, the same for every pair while it
  /// lasts, so the pairs' rows carry T^2 bias_cov (a cold start has not learnt the bias).
  void add_gyro(int64_t t_ns, const Eigen::Vector3d& w_rps,
                const Eigen::Matrix3d& bias_cov = Eigen::Matrix3d::Zero());
  /// One camera frame: its stamp (camera clock) and the body attitude it shows, per-axis sigma.
  /// Waits (queued) until the gyro covers it.
  void add_frame(int64_t stamp_ns, const Eigen::Quaterniond& q_world_body, double sigma_rad);
  [[nodiscard]] double offset_s() const { return st_.offset_s; }
  [[nodiscard]] double sigma_s() const { return st_.sigma_s; }
  [[nodiscard]] int64_t offset_ns() const;
  [[nodiscard]] const VisionTimeOffsetStatus& status() const { return st_; }
  [[nodiscard]] const VisionTimeOffsetParams& params() const { return p_; }
  /// The gyro rotation from t0_ns to t1_ns (filter time, t0 <= t1), body frame, rate linearly
  /// interpolated between samples; false when the samples do not cover [t0, t1].
  [[nodiscard]] bool gyro_rotation(int64_t t0_ns, int64_t t1_ns, Eigen::Quaterniond& out) const;

 private:
  struct Frame {
    int64_t stamp_ns;
    Eigen::Quaterniond q;
    double sigma_rad;
  };
  void process_ready();
  TimeOffsetDecision process(const Frame& f);
  void decide(TimeOffsetDecision d);

  VisionTimeOffsetParams p_;
  VisionTimeOffsetStatus st_;
  double var_s2_ = 0.0;
  Eigen::Matrix3d bias_cov_ = Eigen::Matrix3d::Zero();  ///< the newest gyro sample's, (rad/s)^2
  int64_t last_update_ns_ = -1;
  std::deque<std::pair<int64_t, Eigen::Vector3d>> gyro_;  ///< (t, rate)
  std::deque<Frame> frames_;   ///< processed frames (anchors), newest last
  std::deque<Frame> pending_;  ///< frames waiting for the gyro
};

}  // namespace poise
