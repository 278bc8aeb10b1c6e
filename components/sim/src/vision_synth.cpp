#include "poise/sim/vision_synth.h"

#include "poise/core/attitude.h"

#include <cmath>
#include <stdexcept>

namespace poise {

VisionSynthesizer::VisionSynthesizer(const VisionSynthParams& p) : p_(p), rng_(p.seed) {
  if (!(p_.rate_hz > 0.0) || !(p_.latency_ms >= 0.0) || !(p_.noise_deg >= 0.0) ||
      !(p_.noise_m >= 0.0) || !(p_.dropout_fraction >= 0.0 && p_.dropout_fraction < 1.0) ||
      !(p_.burst_min_s > 0.0 && p_.burst_max_s >= p_.burst_min_s) || !(p_.blackout_s >= 0.0) ||
      (p_.blackout_s > 0.0 && !(p_.blackout_every_s > p_.blackout_s)) ||
      !(std::abs(p_.stamp_offset_ms) <= 1000.0)) {
    throw std::invalid_argument(
        "VisionSynthParams: need rate_hz > 0, latency_ms >= 0, noise >= 0, dropout_fraction in "
        "[0, 1), 0 < burst_min_s <= burst_max_s, blackout_s >= 0 and blackout_every_s > "
        "blackout_s when blackouts are on, |stamp_offset_ms| <= 1000");
  }
  period_ns_ = static_cast<int64_t>(std::llround(1e9 / p_.rate_hz));
  latency_ns_ = static_cast<int64_t>(std::llround(p_.latency_ms * 1e6));
  stamp_offset_ns_ = static_cast<int64_t>(std::llround(p_.stamp_offset_ms * 1e6));
  p_.q_body_camera.normalize();
}

void VisionSynthesizer::advance_visibility(int64_t stamp_ns) {
  if (p_.dropout_fraction <= 0.0) {
    hidden_ = false;
    return;
  }
  while (phase_end_ns_ < 0 || stamp_ns >= phase_end_ns_) {
    const int64_t start = phase_end_ns_ < 0 ? stamp_ns : phase_end_ns_;
    // The first phase is visible; then alternate.
    const bool next_hidden = phase_end_ns_ < 0 ? false : !hidden_;
    double len_s = 0.0;
    const double mean_hidden_s = 0.5 * (p_.burst_min_s + p_.burst_max_s);
    if (next_hidden) {
      std::uniform_real_distribution<double> u(p_.burst_min_s, p_.burst_max_s);
      len_s = u(rng_);
    } else {
      const double mean_visible_s = mean_hidden_s * (1.0 - p_.dropout_fraction) / p_.dropout_fraction;
      std::exponential_distribution<double> e(1.0 / mean_visible_s);
      len_s = e(rng_);
    }
    hidden_ = next_hidden;
    phase_end_ns_ = start + std::max<int64_t>(1, static_cast<int64_t>(std::llround(len_s * 1e9)));
  }
}

void VisionSynthesizer::push_truth(int64_t stamp_ns, const Eigen::Quaterniond& q_world_body,
                                   const Eigen::Vector3d& p_world_body_m, bool valid) {
  if (first_ns_ < 0) {
    first_ns_ = stamp_ns;
    next_capture_ns_ = stamp_ns;
  }
  advance_visibility(stamp_ns);
  blackout_ = false;
  if (p_.blackout_s > 0.0) {
    const double since_s = static_cast<double>(stamp_ns - first_ns_) * 1e-9;
    blackout_ = std::fmod(since_s, p_.blackout_every_s) >= p_.blackout_every_s - p_.blackout_s;
  }
  if (stamp_ns < next_capture_ns_) {
    return;
  }
  while (next_capture_ns_ <= stamp_ns) {
    next_capture_ns_ += period_ns_;
  }
  ++captured_;
  if (hidden_ || blackout_ || !valid || !q_world_body.coeffs().allFinite() || !p_world_body_m.allFinite()) {
    ++dropped_;
    return;
  }
  const Eigen::Vector3d n_r(normal_(rng_), normal_(rng_), normal_(rng_));
  const Eigen::Vector3d n_p(normal_(rng_), normal_(rng_), normal_(rng_));
  const Eigen::Quaterniond q = q_world_body.normalized();
  VisionPose v;
  v.capture_stamp_ns = stamp_ns + stamp_offset_ns_;  // the camera's stamp, not the true capture
  v.q_world_camera = q * quat_exp(n_r * (p_.noise_deg * kRadPerDeg)) * p_.q_body_camera;
  v.p_world_camera_m = p_world_body_m + q * p_.p_body_camera_m + n_p * p_.noise_m;
  v.has_position = true;
  in_flight_.emplace_back(stamp_ns + latency_ns_, v);  // arrives latency after the true capture
}

std::vector<VisionPose> VisionSynthesizer::pop_arrived(int64_t now_ns) {
  std::vector<VisionPose> out;
  while (!in_flight_.empty() && in_flight_.front().first <= now_ns) {
    out.push_back(in_flight_.front().second);
    in_flight_.pop_front();
  }
  return out;
}

}  // namespace poise
