// The selective EKF as an evaluation filter (library poise_selective_ekf_eval): an AttitudeFilter
// that, given a BROAD trial (eval::TrialInputs), feeds itself vision poses synthesised from the
// trial's reference. Registered as "selective" (vision from `poise eval broad --vision-*`) and
// "selective_vision30" (the hybrid benchmark's vision, for `poise bench filters`).
#pragma once

#include "poise/eval/broad.h"
#include "poise/eval/runner.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/sim/vision_synth.h"

#include <memory>
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

class SelectiveEvalFilter : public SelectiveEkfFilter, public eval::TrialInputs {
 public:
  /// `vision.rate_hz` 0 = IMU only. Throws std::invalid_argument for bad vision options.
  SelectiveEvalFilter(const SelectiveEkfParams& p, const VisionSynthParams& vision);
  ~SelectiveEvalFilter() override;
  bool update(const ImuSample& s) override;
  void reset() override;
  void begin_trial(const eval::BroadTrial& trial) override;
  /// Vision returns of the current trial.
  [[nodiscard]] const VisionReturnSteps& return_steps() const { return steps_; }

 private:
  void say_return_steps() const;

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
