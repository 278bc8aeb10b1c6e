// The selective EKF in `poise eval broad` / `poise bench filters`: registers the filter
// "selective" and adds the hybrid-benchmark vision options to `poise eval broad`. Vision poses are
// synthesised from BROAD's reference (opt_quat = q_world_body of the IMU, opt_pos = position of
// the optical body) with noise, latency (delivered late, stamped at capture) and dropout bursts.
#include "poise/eval/selective_ekf_eval.h"

#include "poise/cli/common.h"
#include "poise/eval/filter_registry.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <stdexcept>

namespace poise {

SelectiveEvalFilter::SelectiveEvalFilter(const SelectiveEkfParams& p, const VisionSynthParams& v)
    : SelectiveEkfFilter(p), vision_(v) {
  vision_.q_body_camera = p.q_body_camera;
  vision_.p_body_camera_m = p.p_body_camera_m;
  if (vision_.rate_hz < 0.0) {
    throw std::invalid_argument("vision rate must be >= 0 Hz (0 = no vision)");
  }
  if (vision_.rate_hz > 0.0) {
    VisionSynthesizer check(vision_);  // validates the options early
    (void)check;
  }
}

SelectiveEvalFilter::~SelectiveEvalFilter() { say_return_steps(); }

void SelectiveEvalFilter::say_return_steps() const {
  if (synth_ && steps_.returns > 0) {
    std::fprintf(stderr,
                 "selective: %s: %d vision returns after gaps >= %.0f s (longest %.1f s): largest "
                 "output step within %.0f s of a return %.3f deg\n",
                 trial_name_.c_str(), steps_.returns, VisionReturnSteps::kVisionGapS, steps_.max_gap_s,
                 VisionReturnSteps::kReturnWindowS, steps_.max_step_deg);
  }
}

void SelectiveEvalFilter::reset() {
  say_return_steps();
  SelectiveEkfFilter::reset();
  trial_ = nullptr;
  synth_.reset();
  k_ = 0;
  steps_ = VisionReturnSteps{};
  last_frame_ns_ = -1;
  return_until_ns_ = -1;
  prev_stamp_ns_ = -1;
}

void SelectiveEvalFilter::begin_trial(const eval::BroadTrial& trial) {
  say_return_steps();
  trial_ = &trial;
  trial_name_ = trial.stem;
  k_ = 0;
  steps_ = VisionReturnSteps{};
  last_frame_ns_ = -1;
  return_until_ns_ = -1;
  prev_stamp_ns_ = -1;
  synth_.reset();
  if (vision_.rate_hz > 0.0) {
    synth_ = std::make_unique<VisionSynthesizer>(vision_);
  }
}

bool SelectiveEvalFilter::update(const ImuSample& s) {
  const bool ok = core().update_imu(s);
  if (synth_ && trial_ != nullptr && k_ < trial_->size()) {
    const Eigen::Vector4d& r = trial_->opt_quat_wxyz[k_];
    const bool has_pos = !trial_->opt_pos_m.empty();
    const Eigen::Vector3d p = has_pos ? trial_->opt_pos_m[k_] : Eigen::Vector3d::Zero();
    synth_->push_truth(s.stamp_ns, quat_from_wxyz(r), p, r.allFinite() && p.allFinite());
    for (VisionPose v : synth_->pop_arrived(s.stamp_ns)) {
      v.has_position = has_pos;
      core().update_vision(v);
      if (last_frame_ns_ >= 0) {
        const double gap_s = static_cast<double>(s.stamp_ns - last_frame_ns_) * 1e-9;
        if (gap_s >= VisionReturnSteps::kVisionGapS) {
          ++steps_.returns;
          steps_.max_gap_s = std::max(steps_.max_gap_s, gap_s);
          return_until_ns_ =
              s.stamp_ns + static_cast<int64_t>(VisionReturnSteps::kReturnWindowS * 1e9);
        }
      }
      last_frame_ns_ = s.stamp_ns;
    }
    // Output step not explained by the gyro, inside a return window (this sample included).
    const Eigen::Quaterniond q = core().q_world_body();
    if (ok && prev_stamp_ns_ >= 0 && s.stamp_ns <= return_until_ns_) {
      const double h = static_cast<double>(s.stamp_ns - prev_stamp_ns_) * 1e-9;
      const double step = quat_angle_between(q, prev_q_ * quat_exp(s.gyro_rps * h)) * kDegPerRad;
      steps_.max_step_deg = std::max(steps_.max_step_deg, step);
    }
    if (ok) {
      prev_q_ = q;
      prev_stamp_ns_ = s.stamp_ns;
    }
  }
  ++k_;
  return ok;
}

VisionSynthParams hybrid_benchmark_vision() {
  VisionSynthParams v;
  v.rate_hz = 30.0;
  v.latency_ms = 50.0;
  v.noise_deg = 1.0;
  v.noise_m = 0.01;
  v.dropout_fraction = 0.3;
  v.seed = 1;
  return v;
}

SelectiveEkfParams broad_sensor_params() {
  SelectiveEkfParams p;
  p.imu_delay_s = kBroadImuDelayS;
  return p;
}

namespace cli {

void register_selective_ekf_cli(CLI::App& app) {
  auto vision = std::make_shared<VisionSynthParams>();
  vision->rate_hz = 0.0;  // no vision unless asked for
  vision->noise_deg = 0.0;
  vision->noise_m = 0.0;
  auto make = [](const std::string& cfg, const VisionSynthParams& v) -> std::unique_ptr<AttitudeFilter> {
    const SelectiveEkfParams p = cfg.empty() ? SelectiveEkfParams{} : load_selective_ekf_params(cfg);
    return std::make_unique<SelectiveEvalFilter>(p, v);
  };
  // On BROAD (`poise eval broad`, `poise bench filters`) without --config: BROAD's IMU delay (a
  // property of the dataset's sensor, like a calibration file), said once on stderr so no figure
  // hides it. `poise process` and other users of the table get the plain defaults.
  auto make_broad = [](const VisionSynthParams& v) -> std::unique_ptr<AttitudeFilter> {
    static bool said = false;
    if (!said) {
      said = true;
      std::fprintf(stderr,
                   "selective EKF: BROAD's IMU delay applied, imu_delay_s = %.5f s (measured on trials "
                   "01-18 with `poise calibrate imu-delay`); --config config/filters/selective_ekf.yaml "
                   "runs without it\n",
                   kBroadImuDelayS);
    }
    return std::make_unique<SelectiveEvalFilter>(broad_sensor_params(), v);
  };
  eval::register_filter(
      "selective",
      "selective EKF (paper 002): gyro + Gauss-Newton quaternion + vision, magnetometer gated; "
      "vision from --vision-* options of `poise eval broad`; on BROAD without --config, BROAD's IMU delay",
      [vision, make](const std::string& cfg) { return make(cfg, *vision); },
      [vision, make_broad] { return make_broad(*vision); });
  eval::register_filter(
      "selective_vision30",
      "selective EKF with the hybrid benchmark's vision (30 Hz, 50 ms, 1 deg, 1 cm, 30 % dropout, "
      "seed 1)",
      [make](const std::string& cfg) { return make(cfg, hybrid_benchmark_vision()); },
      [make_broad] { return make_broad(hybrid_benchmark_vision()); });

  CLI::App* eval_group = subcommand_group(app, "eval", "Evaluate estimators on recorded data");
  CLI::App* broad = nullptr;
  try {
    broad = eval_group->get_subcommand("broad");
  } catch (const std::exception&) {
    return;  // poise_eval not linked: nothing to extend
  }
  broad->add_option("--vision-rate", vision->rate_hz,
                    "selective: synthesised vision rate from the reference, Hz (0 = no vision)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  broad->add_option("--vision-latency-ms", vision->latency_ms,
                    "selective: vision delivered this late (stamped at capture), ms")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  broad->add_option("--vision-stamp-offset-ms", vision->stamp_offset_ms,
                    "selective: the vision frame's stamp = its true capture time + this, ms (a "
                    "camera clock or stamping point that is off; it still arrives "
                    "--vision-latency-ms after the true capture), |x| <= 1000")
      ->check(CLI::Range(-1000.0, 1000.0))
      ->capture_default_str();
  broad->add_option("--vision-noise-deg", vision->noise_deg,
                    "selective: vision attitude noise, deg per axis (1 sigma)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  broad->add_option("--vision-noise-m", vision->noise_m,
                    "selective: vision position noise, m per axis (1 sigma)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  broad->add_option("--vision-dropout", vision->dropout_fraction,
                    "selective: fraction of time without vision, in bursts of 1-5 s, [0, 1)")
      ->check(CLI::Range(0.0, 0.99))
      ->capture_default_str();
  broad->add_option("--seed", vision->seed, "selective: seed of the vision noise and dropouts")
      ->capture_default_str();
  broad->add_option("--vision-blackout-s", vision->blackout_s,
                    "selective: long vision blackouts of this length, s (0 = none); the largest "
                    "output step at each return is said on stderr")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  broad->add_option("--vision-blackout-every-s", vision->blackout_every_s,
                    "selective: one blackout (the last --vision-blackout-s) in every this many s")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
}

}  // namespace cli
}  // namespace poise
