// The selective EKF as an evaluation filter (library poise_selective_ekf_eval): an AttitudeFilter
// that, given a BROAD trial (eval::TrialInputs), feeds itself vision poses synthesised from the
// trial's reference. Registered as "selective" (vision from `poise eval broad --vision-*`) and
// "selective_vision30" (the hybrid benchmark's vision, for `poise bench filters`).
#pragma once

#include "poise/eval/broad.h"
#include "poise/eval/runner.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/sim/vision_synth.h"

#include <deque>
#include <memory>
#include <optional>
#include <string>

namespace CLI {
class App;
}

namespace poise {

/// The output's behaviour when vision comes back after a gap (AR: a jump the renderer would show).
/// A return is the first frame delivered after at least kVisionGapS without one; its step is the
/// largest per-sample output rotation not explained by the gyro, angle(q_k, q_{k-1} exp(g_k h)),
/// over the kReturnWindowS after the return.
struct VisionReturnSteps {
  static constexpr double kVisionGapS = 1.0;
  static constexpr double kReturnWindowS = 1.0;
  int returns = 0;
  double max_step_deg = 0.0;     ///< largest step after any return
  double max_gap_s = 0.0;        ///< longest gap seen
};

/// Issue 36 options of `poise eval broad`: the scored output is the pose predicted (or held)
/// predict_horizon_ms ahead, and the time offset estimate is said on stderr.
struct SelectiveEvalOptions {
  /// > 0: the output scored at sample k is the one the filter gave for t_k at the newest sample j
  /// with t_j <= t_k - horizon: predict(t_j + horizon) turned on to t_k with its rate (less than
  /// one sample), or with `hold` the output at j itself; its covariance goes with it. ms
  double predict_horizon_ms = 0.0;
  bool hold = false;
};

class SelectiveEvalFilter : public SelectiveEkfFilter, public eval::TrialInputs {
 public:
  /// `vision.rate_hz` 0 = IMU only. Throws std::invalid_argument for bad vision options.
  SelectiveEvalFilter(const SelectiveEkfParams& p, const VisionSynthParams& vision,
                      const SelectiveEvalOptions& options = {});
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override;
  [[nodiscard]] std::optional<Eigen::Matrix3d> attitude_covariance() const override;
  ~SelectiveEvalFilter() override;
  bool update(const ImuSample& s) override;
  void reset() override;
  void begin_trial(const eval::BroadTrial& trial) override;
  /// Vision returns of the current trial.
  [[nodiscard]] const VisionReturnSteps& return_steps() const { return steps_; }

 private:
  void say_return_steps() const;
  void say_time_offset() const;
  void end_trial();  ///< says the trial's figures on stderr and clears its bookkeeping
  void track_prediction(int64_t stamp_ns);

  VisionSynthParams vision_;
  const eval::BroadTrial* trial_ = nullptr;
  std::unique_ptr<VisionSynthesizer> synth_;
  size_t k_ = 0;
  VisionReturnSteps steps_;
  std::string trial_name_;
  int64_t last_frame_ns_ = -1;      ///< delivery time of the last frame
  int64_t return_until_ns_ = -1;    ///< inside a return window until
  int64_t prev_stamp_ns_ = -1;
  Eigen::Quaterniond prev_q_ = Eigen::Quaterniond::Identity();
  SelectiveEvalOptions options_;
  std::deque<PredictedAttitude> predictions_;  ///< made at earlier samples, oldest first
  bool have_scored_ = false;
  PredictedAttitude scored_;                    ///< the output scored at this sample
  int64_t first_stamp_ns_ = -1;
  int64_t prev_k_stamp_ns_ = -1;
  int64_t motion_ns_ = 0;                       ///< time in BROAD's motion phase so far
  bool offset_at_10s_said_ = false;
  VisionTimeOffsetStatus offset_at_10s_;
};

/// 30 Hz, 50 ms, 1 deg, 1 cm, 30 % dropout, seed 1.
VisionSynthParams hybrid_benchmark_vision();

using eval::kBroadImuDelayS;  // poise/eval/broad.h

/// The selective EKF's defaults with BROAD's IMU delay: what `poise eval broad --filter selective`
/// runs without --config.
SelectiveEkfParams broad_sensor_params();

namespace cli {
/// Registers the filters and the `poise eval broad --vision-*` options.
void register_selective_ekf_cli(CLI::App& app);
}  // namespace cli

}  // namespace poise
