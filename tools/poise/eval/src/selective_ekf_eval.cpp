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

SelectiveEvalFilter::SelectiveEvalFilter(const SelectiveEkfParams& p, const VisionSynthParams& v,
                                         const SelectiveEvalOptions& options)
    : SelectiveEkfFilter(p), vision_(v), options_(options) {
  if (!(options_.predict_horizon_ms >= 0.0 && options_.predict_horizon_ms <= 200.0)) {
    throw std::invalid_argument("--predict-horizon-ms must be in [0, 200] ms");
  }
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

SelectiveEvalFilter::~SelectiveEvalFilter() {
  say_return_steps();
  say_time_offset();
}

void SelectiveEvalFilter::say_time_offset() const {
  const VisionTimeOffsetStatus& now = core().vision_time_offset();
  if (!synth_ || !now.estimating || first_stamp_ns_ < 0) {
    return;
  }
  // the truth: a frame stamped s shows the pose at s - stamp_offset (offset = -stamp_offset)
  const double truth_ms = -vision_.stamp_offset_ms;
  std::fprintf(stderr,
               "selective: %s: time offset (truth %.1f ms): after 10 s of motion %.2f ms (error %.2f, sigma %.2f, "
               "%s), at the end %.2f ms (error %.2f, sigma %.2f, %s); pairs used %llu, rejected %llu\n",
               trial_name_.c_str(), truth_ms, offset_at_10s_.offset_s * 1e3,
               offset_at_10s_.offset_s * 1e3 - truth_ms, offset_at_10s_.sigma_s * 1e3,
               offset_at_10s_.converged ? "converged" : "not converged", now.offset_s * 1e3,
               now.offset_s * 1e3 - truth_ms, now.sigma_s * 1e3, now.converged ? "converged" : "not converged",
               static_cast<unsigned long long>(now.used), static_cast<unsigned long long>(now.rejected));
}

Eigen::Quaterniond SelectiveEvalFilter::q_world_body() const {
  if (options_.predict_horizon_ms > 0.0) {
    return have_scored_ ? scored_.q_world_body : Eigen::Quaterniond::Identity();
  }
  return SelectiveEkfFilter::q_world_body();
}

std::optional<Eigen::Matrix3d> SelectiveEvalFilter::attitude_covariance() const {
  if (options_.predict_horizon_ms > 0.0) {
    return have_scored_ ? std::optional<Eigen::Matrix3d>(scored_.covariance) : std::nullopt;
  }
  return SelectiveEkfFilter::attitude_covariance();
}

void SelectiveEvalFilter::track_prediction(int64_t stamp_ns) {
  // made now for t + horizon (or held), scored at the first later sample at or after it
  const auto horizon_ns = static_cast<int64_t>(std::llround(options_.predict_horizon_ms * 1e6));
  PredictedAttitude p = core().predict(stamp_ns + horizon_ns);
  if (options_.hold) {
    p = core().predict(stamp_ns);  // the newest output, held
    p.stamp_ns = stamp_ns + horizon_ns;
    p.rate_rps.setZero();
  }
  predictions_.push_back(p);
  have_scored_ = false;
  while (!predictions_.empty() && predictions_.front().stamp_ns <= stamp_ns) {
    scored_ = predictions_.front();
    predictions_.pop_front();
    have_scored_ = true;
  }
  if (have_scored_) {  // the last sample's gap (less than one sample) with the same rate
    const double h = static_cast<double>(stamp_ns - scored_.stamp_ns) * 1e-9;
    scored_.q_world_body = (scored_.q_world_body * quat_exp(scored_.rate_rps * h)).normalized();
  }
}

void SelectiveEvalFilter::say_return_steps() const {
  if (synth_ && steps_.returns > 0) {
    std::fprintf(stderr,
                 "selective: %s: %d vision returns after gaps >= %.0f s (longest %.1f s): largest "
                 "output step within %.0f s of a return %.3f deg\n",
                 trial_name_.c_str(), steps_.returns, VisionReturnSteps::kVisionGapS, steps_.max_gap_s,
                 VisionReturnSteps::kReturnWindowS, steps_.max_step_deg);
  }
}

void SelectiveEvalFilter::end_trial() {
  say_return_steps();
  say_time_offset();
  k_ = 0;
  steps_ = VisionReturnSteps{};
  last_frame_ns_ = -1;
  return_until_ns_ = -1;
  prev_stamp_ns_ = -1;
  predictions_.clear();
  have_scored_ = false;
  first_stamp_ns_ = -1;
  prev_k_stamp_ns_ = -1;
  motion_ns_ = 0;
  offset_at_10s_said_ = false;
  offset_at_10s_ = VisionTimeOffsetStatus{};
  synth_.reset();
}

void SelectiveEvalFilter::reset() {
  end_trial();
  SelectiveEkfFilter::reset();
  trial_ = nullptr;
}

void SelectiveEvalFilter::begin_trial(const eval::BroadTrial& trial) {
  end_trial();
  trial_ = &trial;
  trial_name_ = trial.stem;
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
  // motion time: samples in BROAD's motion phase (the rest before it shows no offset)
  const bool moving = trial_ != nullptr && k_ < trial_->movement.size() && trial_->movement[k_] != 0;
  if (moving && prev_k_stamp_ns_ >= 0) {
    motion_ns_ += s.stamp_ns - prev_k_stamp_ns_;
  }
  prev_k_stamp_ns_ = s.stamp_ns;
  if (first_stamp_ns_ < 0) {
    first_stamp_ns_ = s.stamp_ns;
  }
  if (!offset_at_10s_said_ && motion_ns_ >= static_cast<int64_t>(10e9)) {
    offset_at_10s_ = core().vision_time_offset();
    offset_at_10s_said_ = true;
  }
  if (options_.predict_horizon_ms > 0.0 && ok) {
    track_prediction(s.stamp_ns);
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
  auto options = std::make_shared<SelectiveEvalOptions>();
  vision->rate_hz = 0.0;  // no vision unless asked for
  vision->noise_deg = 0.0;
  vision->noise_m = 0.0;
  auto make = [options](const std::string& cfg, const VisionSynthParams& v) -> std::unique_ptr<AttitudeFilter> {
    const SelectiveEkfParams p = cfg.empty() ? SelectiveEkfParams{} : load_selective_ekf_params(cfg);
    return std::make_unique<SelectiveEvalFilter>(p, v, *options);
  };
  // On BROAD (`poise eval broad`, `poise bench filters`) without --config: BROAD's IMU delay (a
  // property of the dataset's sensor, like a calibration file), said once on stderr so no figure
  // hides it. `poise process` and other users of the table get the plain defaults.
  auto make_broad = [options](const VisionSynthParams& v) -> std::unique_ptr<AttitudeFilter> {
    static bool said = false;
    if (!said) {
      said = true;
      std::fprintf(stderr,
                   "selective EKF: BROAD's IMU delay applied, imu_delay_s = %.5f s (measured on trials "
                   "01-18 with `poise calibrate imu-delay`); --config config/filters/selective_ekf.yaml "
                   "runs without it\n",
                   kBroadImuDelayS);
    }
    return std::make_unique<SelectiveEvalFilter>(broad_sensor_params(), v, *options);
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
  broad->add_option("--predict-horizon-ms", options->predict_horizon_ms,
                    "selective: score the pose predicted this far ahead (SelectiveEkf::predict) "
                    "against the truth at the predicted instant, ms in [0, 200] (0 = the output)")
      ->check(CLI::Range(0.0, 200.0))
      ->capture_default_str();
  broad->add_flag("--predict-hold", options->hold,
                  "selective: with --predict-horizon-ms, score the newest output held instead (the "
                  "baseline of the prediction)");
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
