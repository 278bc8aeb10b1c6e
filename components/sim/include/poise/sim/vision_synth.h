// VisionSynthesizer: camera poses synthesised from a truth stream (simulator truth or BROAD's
// optical reference) for scenario tests and the hybrid benchmark. Seeded, no clocks.
//
// Model
//   capture instants every 1/rate_hz from the first truth stamp (taken at the first truth sample
//   at or after each instant, stamped with that sample's stamp);
//   q_world_camera = q_world_body (x) exp(n_r) (x) q_body_camera, n_r ~ N(0, noise_deg^2 I) (body);
//   p_world_camera = p + R(q_true) p_body_camera + n_p,  n_p ~ N(0, noise_m^2 I);
//   delivered at capture + latency (pop_arrived), stamped at capture + stamp_offset_ms (0: the
//   true capture time; else a camera whose clock or stamping point is off, issue 36);
//   dropouts: alternating visible / hidden periods; hidden lengths uniform in
//   [burst_min_s, burst_max_s], visible lengths exponential with the mean that makes the hidden
//   fraction equal dropout_fraction (the tag leaving the view). Truth rows marked invalid (NaN
//   reference) give no frame either.
//   long blackouts (the user walks away from the tags): no frame while
//   (t - t_first) mod blackout_every_s >= blackout_every_s - blackout_s, i.e. the last blackout_s
//   of every blackout_every_s (first one ending at blackout_every_s); 0 = none.
#pragma once

#include "poise/selective_ekf/selective_ekf.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <deque>
#include <random>
#include <vector>

namespace poise {

struct VisionSynthParams {
  double rate_hz = 30.0;
  double latency_ms = 0.0;
  /// the frame's stamp = true capture time + this, ms (|x| <= 1000; arrival unchanged)
  double stamp_offset_ms = 0.0;
  double noise_deg = 1.0;
  double noise_m = 0.01;
  double dropout_fraction = 0.0;   ///< [0, 1)
  double burst_min_s = 1.0;
  double burst_max_s = 5.0;
  double blackout_s = 0.0;         ///< long blackout length, s (0 = none)
  double blackout_every_s = 0.0;   ///< blackout period, s (> blackout_s when blackout_s > 0)
  uint64_t seed = 1;
  Eigen::Quaterniond q_body_camera = Eigen::Quaterniond::Identity();
  Eigen::Vector3d p_body_camera_m{0.0, 0.0, 0.0};
};

class VisionSynthesizer {
 public:
  /// Throws std::invalid_argument for rate <= 0, negative latency/noise, a fraction outside [0, 1)
  /// or a stamp offset not finite or beyond 1 s.
  explicit VisionSynthesizer(const VisionSynthParams& p);

  /// Offers the truth at `stamp_ns`; `valid` false for rows without a reference.
  void push_truth(int64_t stamp_ns, const Eigen::Quaterniond& q_world_body,
                  const Eigen::Vector3d& p_world_body_m, bool valid);
  /// Frames whose arrival time (capture + latency) is <= now_ns, oldest first.
  std::vector<VisionPose> pop_arrived(int64_t now_ns);

  [[nodiscard]] uint64_t frames_captured() const { return captured_; }
  [[nodiscard]] uint64_t frames_dropped() const { return dropped_; }
  /// True when `stamp_ns` fell in a hidden (dropout) period (after push_truth of that stamp).
  [[nodiscard]] bool hidden() const { return hidden_; }
  /// True when `stamp_ns` fell in a long blackout (after push_truth of that stamp).
  [[nodiscard]] bool blackout() const { return blackout_; }

 private:
  void advance_visibility(int64_t stamp_ns);

  VisionSynthParams p_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  int64_t first_ns_ = -1;
  int64_t next_capture_ns_ = -1;
  int64_t period_ns_ = 0;
  int64_t latency_ns_ = 0;
  int64_t stamp_offset_ns_ = 0;
  int64_t phase_end_ns_ = -1;
  bool hidden_ = false;
  bool blackout_ = false;
  std::deque<std::pair<int64_t, VisionPose>> in_flight_;  ///< (arrival, frame)
  uint64_t captured_ = 0;
  uint64_t dropped_ = 0;
};

}  // namespace poise
