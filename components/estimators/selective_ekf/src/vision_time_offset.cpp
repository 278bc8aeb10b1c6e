// The camera-IMU time offset estimated online (model: poise/selective_ekf/vision_time_offset.h).
#include "poise/selective_ekf/vision_time_offset.h"

#include "aid.h"
#include "poise/core/attitude.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace poise {
namespace {

using selective_ekf_aids::kNsToS;
/// central-difference step of dr/dd, s
constexpr double kDiffStepS = 0.001;
/// frames waiting for the gyro are dropped beyond this many (a stalled IMU)
constexpr size_t kMaxPending = 64;
/// a longer gap between gyro samples is a time jump: nothing is interpolated across it, s
constexpr double kMaxGyroGapS = 0.5;

int64_t to_ns(double s) { return selective_ekf_aids::seconds_to_ns(s); }

}  // namespace

const char* to_string(TimeOffsetDecision d) {
  switch (d) {
    case TimeOffsetDecision::kNone: return "none";
    case TimeOffsetDecision::kUsed: return "used";
    case TimeOffsetDecision::kRejectedGate: return "rejected_gate";
    case TimeOffsetDecision::kNoPair: return "no_pair";
    case TimeOffsetDecision::kNoMotion: return "no_motion";
    case TimeOffsetDecision::kNoGyro: return "no_gyro";
    case TimeOffsetDecision::kNotEstimated: return "not_estimated";
    case TimeOffsetDecision::kCount: break;
  }
  return "unknown";
}

VisionTimeOffsetEstimator::VisionTimeOffsetEstimator(const VisionTimeOffsetParams& p) : p_(p) {
  auto need = [](bool ok, const char* what) {
    if (!ok) {
      throw std::invalid_argument(std::string("vision time offset: ") + what);
    }
  };
  need(std::isfinite(p_.max_abs_s) && p_.max_abs_s > 0.0 && p_.max_abs_s <= 0.2, "max_abs_s in (0, 0.2] (s)");
  need(std::abs(p_.prior_s) <= p_.max_abs_s, "vision_time_offset_s (the prior) in [-0.2, 0.2] (s)");
  need(p_.prior_sigma_s >= 0.0 && p_.prior_sigma_s <= 0.2,
       "vision_time_offset_sigma_s in [0, 0.2] (s; 0 = not estimated)");
  need(p_.walk_s_sqrt_s >= 0.0 && p_.walk_s_sqrt_s <= 0.01,
       "vision_time_offset_walk_s_sqrt_s in [0, 0.01] (s/sqrt(s))");
  need(p_.baseline_s > 0.0 && p_.max_pair_s > p_.baseline_s && p_.max_pair_s <= 2.0,
       "0 < baseline_s < max_pair_s <= 2 (s)");
  need(p_.min_rate_change_rps >= 0.0 && std::isfinite(p_.min_rate_change_rps), "min_rate_change_rps >= 0 (rad/s)");
  need(p_.gate_sigma > 0.0 && std::isfinite(p_.gate_sigma), "gate_sigma > 0");
  need(p_.converged_sigma_s > 0.0 && std::isfinite(p_.converged_sigma_s), "converged_sigma_s > 0 (s)");
  need(p_.sigma_gyro_rps >= 0.0 && std::isfinite(p_.sigma_gyro_rps), "sigma_gyro_rps >= 0 (rad/s)");
  reset();
}

void VisionTimeOffsetEstimator::reset() {
  st_ = VisionTimeOffsetStatus{};
  st_.offset_s = p_.prior_s;
  st_.sigma_s = p_.prior_sigma_s;
  st_.estimating = p_.prior_sigma_s > 0.0;
  st_.converged = !st_.estimating || st_.sigma_s <= p_.converged_sigma_s;
  var_s2_ = p_.prior_sigma_s * p_.prior_sigma_s;
  bias_cov_.setZero();
  last_update_ns_ = -1;
  gyro_.clear();
  frames_.clear();
  pending_.clear();
}

int64_t VisionTimeOffsetEstimator::offset_ns() const { return to_ns(st_.offset_s); }

void VisionTimeOffsetEstimator::add_gyro(int64_t t_ns, const Eigen::Vector3d& w_rps,
                                         const Eigen::Matrix3d& bias_cov) {
  if (!st_.estimating || !w_rps.allFinite()) {
    return;
  }
  if (bias_cov.allFinite()) {
    bias_cov_ = 0.5 * (bias_cov + bias_cov.transpose());
  }
  if (!gyro_.empty() && (t_ns <= gyro_.back().first || t_ns - gyro_.back().first > to_ns(kMaxGyroGapS))) {
    gyro_.clear();  // time went back or jumped (the filter re-anchored): start the buffer again
    frames_.clear();
  }
  gyro_.emplace_back(t_ns, w_rps);
  // keep what the oldest possible pair needs: max_pair_s before the newest frame, shifted
  const int64_t keep_ns = to_ns(p_.max_pair_s + 2.0 * p_.max_abs_s + 0.5);
  while (gyro_.size() > 2 && gyro_[1].first < t_ns - keep_ns) {
    gyro_.pop_front();
  }
  process_ready();
}

void VisionTimeOffsetEstimator::add_frame(int64_t stamp_ns, const Eigen::Quaterniond& q_world_body,
                                          double sigma_rad) {
  if (!st_.estimating) {
    decide(TimeOffsetDecision::kNotEstimated);
    return;
  }
  if (!q_world_body.coeffs().allFinite() || !(sigma_rad > 0.0) || !std::isfinite(sigma_rad)) {
    return;  // the filter counts bad frames; nothing to learn from one
  }
  if (pending_.size() >= kMaxPending) {
    pending_.pop_front();
  }
  pending_.push_back({stamp_ns, q_world_body.normalized(), sigma_rad});
  process_ready();
}

void VisionTimeOffsetEstimator::process_ready() {
  if (gyro_.empty()) {
    return;
  }
  const int64_t newest = gyro_.back().first;
  const int64_t margin = to_ns(kDiffStepS) + 1;
  while (!pending_.empty() && pending_.front().stamp_ns + offset_ns() + margin <= newest) {
    const Frame f = pending_.front();
    pending_.pop_front();
    decide(process(f));
    // the frame is an anchor for later ones (sorted by stamp; an out-of-order one is not kept)
    if (frames_.empty() || f.stamp_ns > frames_.back().stamp_ns) {
      frames_.push_back(f);
    }
    while (!frames_.empty() && frames_.front().stamp_ns < f.stamp_ns - to_ns(p_.max_pair_s)) {
      frames_.pop_front();
    }
  }
}

bool VisionTimeOffsetEstimator::gyro_rotation(int64_t t0_ns, int64_t t1_ns, Eigen::Quaterniond& out) const {
  if (gyro_.size() < 2 || t0_ns < gyro_.front().first || t1_ns > gyro_.back().first || t1_ns < t0_ns) {
    return false;
  }
  // first sample interval containing t0
  auto it = std::upper_bound(gyro_.begin(), gyro_.end(), t0_ns,
                             [](int64_t t, const std::pair<int64_t, Eigen::Vector3d>& g) { return t < g.first; });
  size_t i = static_cast<size_t>(it - gyro_.begin());
  i = std::max<size_t>(i, 1);
  auto rate_at = [this](size_t k, int64_t t) {  // linear between samples k-1 and k
    const auto& a = gyro_[k - 1];
    const auto& b = gyro_[k];
    const double u = static_cast<double>(t - a.first) / static_cast<double>(b.first - a.first);
    return Eigen::Vector3d(a.second + u * (b.second - a.second));
  };
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  int64_t t = t0_ns;
  for (; i < gyro_.size() && t < t1_ns; ++i) {
    const int64_t end = std::min(gyro_[i].first, t1_ns);
    if (end <= t) {
      continue;
    }
    // exact for a rate linear in time up to second order: the midpoint rate over the piece
    const Eigen::Vector3d w = rate_at(i, t + (end - t) / 2);
    q = q * quat_exp(w * (static_cast<double>(end - t) * kNsToS));
    t = end;
  }
  out = q.normalized();
  return true;
}

TimeOffsetDecision VisionTimeOffsetEstimator::process(const Frame& f) {
  // the newest earlier frame at least baseline_s before this one
  const Frame* a = nullptr;
  for (auto it = frames_.rbegin(); it != frames_.rend(); ++it) {
    const int64_t gap = f.stamp_ns - it->stamp_ns;
    if (gap >= to_ns(p_.baseline_s)) {
      if (gap <= to_ns(p_.max_pair_s)) {
        a = &*it;
      }
      break;
    }
  }
  if (a == nullptr) {
    return TimeOffsetDecision::kNoPair;
  }
  // the offset's random walk since the last update
  if (last_update_ns_ >= 0 && f.stamp_ns > last_update_ns_) {
    var_s2_ += p_.walk_s_sqrt_s * p_.walk_s_sqrt_s * static_cast<double>(f.stamp_ns - last_update_ns_) * kNsToS;
  }
  last_update_ns_ = std::max(last_update_ns_, f.stamp_ns);
  st_.sigma_s = std::sqrt(var_s2_);
  const Eigen::Quaterniond v = a->q.conjugate() * f.q;
  auto residual = [&](double d_s, Eigen::Vector3d& r) {
    const int64_t d = to_ns(d_s);
    Eigen::Quaterniond g;
    if (!gyro_rotation(a->stamp_ns + d, f.stamp_ns + d, g)) {
      return false;
    }
    r = quat_log(g.conjugate() * quat_align_sign(v, g));
    return true;
  };
  const double d0 = st_.offset_s;
  Eigen::Vector3d r0;
  Eigen::Vector3d rp;
  Eigen::Vector3d rm;
  if (!residual(d0, r0) || !residual(d0 + kDiffStepS, rp) || !residual(d0 - kDiffStepS, rm)) {
    return TimeOffsetDecision::kNoGyro;
  }
  // r(d) ~ r0 + (dr/dd) (d - d0) and r(d_true) = noise: y = -r0 = (dr/dd) (d_true - d0) + n
  const Eigen::Vector3d jac = (rp - rm) / (2.0 * kDiffStepS);
  st_.innovation_rad = r0.norm();
  if (jac.norm() < p_.min_rate_change_rps) {
    st_.test_ratio = 0.0;
    return TimeOffsetDecision::kNoMotion;
  }
  const double pair_s = static_cast<double>(f.stamp_ns - a->stamp_ns) * kNsToS;
  const double dt_gyro_s = gyro_.size() > 1 ? static_cast<double>(gyro_.back().first - gyro_.front().first) *
                                                  kNsToS / static_cast<double>(gyro_.size() - 1)
                                            : 0.0;
  // both frames' noise, doubled (each frame is in about two pairs), plus the gyro's white noise
  const double r_var = 2.0 * (a->sigma_rad * a->sigma_rad + f.sigma_rad * f.sigma_rad) +
                       p_.sigma_gyro_rps * p_.sigma_gyro_rps * dt_gyro_s * pair_s;
  // and the removed bias's error over the pair (a rotation db T)
  const Eigen::Matrix3d s = jac * jac.transpose() * var_s2_ + Eigen::Matrix3d::Identity() * r_var +
                            (pair_s * pair_s) * bias_cov_;
  const Eigen::Matrix3d s_inv = s.inverse();
  const Eigen::Vector3d y = -r0;
  const double nis = y.dot(s_inv * y);
  st_.test_ratio = nis / (p_.gate_sigma * p_.gate_sigma);
  if (st_.test_ratio > 1.0) {
    ++st_.rejected;
    return TimeOffsetDecision::kRejectedGate;
  }
  const Eigen::RowVector3d k = var_s2_ * jac.transpose() * s_inv;
  st_.offset_s = std::clamp(d0 + k.dot(y), -p_.max_abs_s, p_.max_abs_s);
  var_s2_ = std::max(var_s2_ * (1.0 - k.dot(jac)), 0.0);
  st_.sigma_s = std::sqrt(var_s2_);
  st_.converged = st_.sigma_s <= p_.converged_sigma_s;
  st_.last_used_stamp_ns = f.stamp_ns;
  ++st_.used;
  return TimeOffsetDecision::kUsed;
}

void VisionTimeOffsetEstimator::decide(TimeOffsetDecision d) {
  st_.last = d;
  ++st_.by_decision[static_cast<size_t>(d)];
}

// ------------------------------------------------------------------ the selective EKF's use
namespace selective_ekf_aids {

VisionTimeOffsetParams time_offset_params(const SelectiveEkfParams& p) {
  VisionTimeOffsetParams t;
  t.prior_s = p.vision_time_offset_s;
  t.prior_sigma_s = p.vision_time_offset_sigma_s;
  t.walk_s_sqrt_s = p.vision_time_offset_walk_s_sqrt_s;
  t.sigma_gyro_rps = p.sigma_gyro_rps;
  return t;
}

void apply_time_offset(VisionTimeOffsetEstimator& est, const SelectiveEkfParams& p, const Eigen::Vector3d& w_rps,
                       VisionPose& v) {
  if (!est.status().estimating) {
    v.capture_stamp_ns += est.offset_ns();  // the configured offset, exact
    return;
  }
  const VisionMeasurement m = vision_measurement(p, v);
  est.add_frame(v.capture_stamp_ns, m.q_world_body, m.sigma_rad);
  v.capture_stamp_ns += est.offset_ns();
  // the attitude at a capture time known to sigma_offset is known to |w| sigma_offset less
  const double timing_rad = w_rps.norm() * est.sigma_s();
  v.sigma_rad = std::sqrt(m.sigma_rad * m.sigma_rad + timing_rad * timing_rad);
  if (m.has_attitude_covariance) {
    v.attitude_covariance_world += Eigen::Matrix3d::Identity() * timing_rad * timing_rad;
  }
}

}  // namespace selective_ekf_aids
}  // namespace poise
