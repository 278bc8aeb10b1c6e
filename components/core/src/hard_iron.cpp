#include "poise/core/hard_iron.h"

#include "poise/core/params_check.h"

#include <Eigen/Dense>

#include <cmath>
#include <utility>

namespace poise {

void HardIronParams::validate(const char* filter) const {
  const ParamCheck check(filter);
  check.positive(prior_sigma_ut, "prior_sigma_ut", "uT");
  check.positive(noise_ut, "noise_ut", "uT");
  check.non_negative(timing_s, "timing_s", "s");
  check.non_negative(walk_ut_per_sqrt_s, "walk_ut_per_sqrt_s", "uT/sqrt(s)");
  check.positive(lag_s, "lag_s", "s");
  check.positive(min_rotation_rad, "min_rotation_rad", "rad");
  check.require(min_rotation_rad < M_PI, "min_rotation_rad", "< pi (rad)");
  check.positive(gate_chi2, "gate_chi2", "(chi-square, 3 dof)");
  check.positive(reset_after_s, "reset_after_s", "s");
  check.positive(converged_sigma_ut, "converged_sigma_ut", "uT");
  check.non_negative(min_applied_ut, "min_applied_ut", "uT");
  check.non_negative(consistency_tau_s, "consistency_tau_s", "s, 0 = no check");
  check.non_negative(removed_log_lr, "removed_log_lr", "0 = no test");
  check.require(removed_log_lr <= 1e6, "removed_log_lr", "<= 1e6");
  check.positive(removed_tau_s, "removed_tau_s", "s");
  check.require(removed_tau_s <= 1e6, "removed_tau_s", "<= 1e6 (s)");
  check.non_negative(noise_tau_s, "noise_tau_s", "s, 0 = noise_ut's");
  check.require(noise_tau_s <= 1e6, "noise_tau_s", "<= 1e6 (s)");
  check.positive(max_dt_s, "max_dt_s", "s");
  check.require(lag_s < 100.0, "lag_s", "< 100 (s)");
  check.positive(max_mag_ut, "max_mag_ut", "uT");
  check.positive(max_gyro_rps, "max_gyro_rps", "rad/s");
  // A grid of readings lag_s apart in ns, and squares of the uT / rad/s values: bounded so that
  // neither divides by a zero step, loops per grid instant nor overflows to inf.
  check.require(lag_s >= 0.001, "lag_s", ">= 0.001 (s)");
  check.require(prior_sigma_ut <= 1e4, "prior_sigma_ut", "<= 1e4 (uT)");
  check.require(noise_ut <= 1e4, "noise_ut", "<= 1e4 (uT)");
  check.require(timing_s <= 1.0, "timing_s", "<= 1 (s)");
  check.require(walk_ut_per_sqrt_s <= 1e3, "walk_ut_per_sqrt_s", "<= 1e3 (uT/sqrt(s))");
  check.require(converged_sigma_ut <= 1e4, "converged_sigma_ut", "<= 1e4 (uT)");
  check.require(min_applied_ut <= 1e4, "min_applied_ut", "<= 1e4 (uT)");
  check.require(max_mag_ut <= 1e6, "max_mag_ut", "<= 1e6 (uT)");
  check.require(max_gyro_rps <= 1e4, "max_gyro_rps", "<= 1e4 (rad/s)");
}

const char* to_string(HardIronStep s) {
  switch (s) {
    case HardIronStep::kUpdated: return "updated";
    case HardIronStep::kWarmingUp: return "warming_up";
    case HardIronStep::kInterval: return "interval";
    case HardIronStep::kNotEnoughRotation: return "not_enough_rotation";
    case HardIronStep::kGated: return "gated";
    case HardIronStep::kReset: return "reset";
    case HardIronStep::kStep: return "step";
    case HardIronStep::kGap: return "gap";
    case HardIronStep::kRejectedInput: return "rejected_input";
    case HardIronStep::kNoMagnetometer: return "no_magnetometer";
    case HardIronStep::kCount: break;
  }
  return "unknown";
}

HardIronEstimator::HardIronEstimator(const HardIronParams& p) : p_(p) {
  p_.validate();
  lag_ns_ = static_cast<int64_t>(std::llround(p_.lag_s * 1e9));
  reset();
}

void HardIronEstimator::reset() {
  b_.setZero();
  P_ = Eigen::Matrix3d::Identity() * (p_.prior_sigma_ut * p_.prior_sigma_ut);
  P_err_ = P_;
  shared_.setZero();
  gain_.setZero();
  nis_sum_ = 0.0;
  nis_w_ = 0.0;
  start_ = Entry{};
  have_start_ = false;
  have_before_ = false;
  prev_ = Entry{};
  next_grid_ns_ = 0;
  have_last_ = false;
  last_ns_ = 0;
  q_.setIdentity();
  last_w_.setZero();
  last_w_ns_ = 0;
  have_w_ = false;
  refused_s_ = 0.0;
  have_step_ = false;
  step_provisional_ = false;
  raw_change2_ = 0.0;
  cor_change2_ = 0.0;
  change_weight_ = 0.0;
  clear_field();
  report_ = HardIronReport{};
  refresh();
}

const HardIronReport& HardIronEstimator::finish(HardIronStep s) {
  report_.step = s;
  ++report_.counts[static_cast<size_t>(s)];
  return report_;
}

void HardIronEstimator::refresh() {
  report_.converged = (P_.diagonal().array() < p_.converged_sigma_ut * p_.converged_sigma_ut).all();
  // (undecided, no comparison that turned since the last step or reset: consistent)
  report_.consistent = !(p_.consistency_tau_s > 0.0) || change_weight_ == 0.0 || cor_change2_ < raw_change2_;
  const bool large = b_.squaredNorm() > p_.min_applied_ut * p_.min_applied_ut && report_.consistent;
  applied_ = report_.converged && large;
  report_.present = applied_ || (large && b_.dot(P_.ldlt().solve(b_)) > p_.gate_chi2);
  if (!report_.present) {
    report_.removed_llr = 0.0;  // the test is of an offset that is there
  }
}

void HardIronEstimator::clear_field() {
  field_sum_.setZero();
  frame_sum_.setZero();
  field_w_ = 0.0;
  field_var2_ = 0.0;
  field_refused_s_ = 0.0;
}

bool HardIronEstimator::removed(const Eigen::Matrix3d& r_k, const Eigen::Vector3d& m_k, double var_ut2,
                                double interval_s) {
  if (!(p_.removed_log_lr > 0.0)) {
    return false;
  }
  const double keep = std::exp(-interval_s / p_.removed_tau_s);
  field_sum_ *= keep;
  frame_sum_ *= keep;
  field_w_ *= keep;
  field_var2_ *= keep * keep;
  const Eigen::Vector3d z = r_k * m_k;  // the reading seen from the gyro frame
  bool fits = true;  // the estimate fits k (or nothing is judged): k joins the field followed
  if (report_.present && field_w_ > 0.0) {
    // the field followed, f(b) = mean(z) - mean(R) b; "no offset": z = f(b_hat), its error
    // mean(R) (b_hat - b); "the estimate": z - R_k b_hat = f(b_hat), its error (mean(R) - R_k) (b_hat - b)
    const Eigen::Matrix3d mean_r = frame_sum_ / field_w_;
    const Eigen::Vector3d e0 = z - field_sum_ / field_w_ + mean_r * b_;
    const Eigen::Vector3d e1 = e0 - r_k * b_;
    const Eigen::Matrix3d noise = Eigen::Matrix3d::Identity() * (var_ut2 + field_var2_ / (field_w_ * field_w_));
    const Eigen::Matrix3d d = mean_r - r_k;
    const Eigen::Matrix3d s0 = noise + mean_r * P_ * mean_r.transpose();
    const Eigen::Matrix3d s1 = noise + d * P_ * d.transpose();
    const double nis0 = e0.dot(s0.ldlt().solve(e0));
    const double nis1 = e1.dot(s1.ldlt().solve(e1));
    report_.removed_nis_none = nis0;
    report_.removed_nis_estimate = nis1;
    fits = nis1 <= p_.gate_chi2;
    if (!fits && !(nis0 <= p_.gate_chi2)) {
      // neither fits: the field itself moves (a disturbance, the magnet on its way off), no
      // evidence either way and nothing followed; a field refused for removed_tau_s (the time it
      // is taken as constant over) has moved for good and is followed anew
      field_refused_s_ += interval_s;
      if (field_refused_s_ >= p_.removed_tau_s) {
        clear_field();
      }
      return false;
    }
    field_refused_s_ = 0.0;
    const double llr = 0.5 * (nis1 - nis0) + 0.5 * std::log(s1.determinant() / s0.determinant());
    report_.removed_llr = std::max(0.0, report_.removed_llr + (std::isfinite(llr) ? llr : 0.0));
    if (report_.removed_llr >= p_.removed_log_lr) {
      return true;
    }
  }
  if (fits) {
    field_sum_ += z;
    frame_sum_ += r_k;
    field_w_ += 1.0;
    field_var2_ += var_ut2;
  }
  return false;
}

bool HardIronEstimator::usable(int64_t stamp_ns, const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& mag_ut) const {
  // Squared norms: a NaN gives NaN, an infinite or huge (1e308: overflows) component +inf, and
  // both fail the comparison, so no finiteness check is needed before them. The stamp bound
  // (as check_imu_sample's) keeps every stamp difference and the grid of readings in int64.
  return stamp_ns >= 0 && stamp_ns <= kMaxStampNs && mag_ut.squaredNorm() <= p_.max_mag_ut * p_.max_mag_ut &&
         gyro_rps.squaredNorm() <= p_.max_gyro_rps * p_.max_gyro_rps;
}

double HardIronEstimator::reading_var(const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& mag_ut) const {
  const double timing_ut = gyro_rps.norm() * p_.timing_s * mag_ut.norm();
  return p_.noise_ut * p_.noise_ut + timing_ut * timing_ut;
}

void HardIronEstimator::consistency(const Eigen::Vector3d& m_j, const Eigen::Vector3d& m_k, double interval_s) {
  if (!(p_.consistency_tau_s > 0.0)) {
    return;
  }
  const double keep = std::exp(-interval_s / p_.consistency_tau_s);
  const double raw = m_k.norm() - m_j.norm();
  const double cor = (m_k - b_).norm() - (m_j - b_).norm();
  raw_change2_ = keep * raw_change2_ + raw * raw;
  cor_change2_ = keep * cor_change2_ + cor * cor;
  change_weight_ = keep * change_weight_ + 1.0;
  report_.raw_norm_change_ut = std::sqrt(raw_change2_ / change_weight_);
  report_.corrected_norm_change_ut = std::sqrt(cor_change2_ / change_weight_);
  refresh();
}

const HardIronReport& HardIronEstimator::update(const ImuSample& s) {
  if (!s.has_mag || !s.has_gyro) {
    return finish(HardIronStep::kNoMagnetometer);
  }
  return update(s.stamp_ns, s.gyro_rps, s.mag_ut);
}

const HardIronReport& HardIronEstimator::update(int64_t stamp_ns, const Eigen::Vector3d& gyro_rps,
                                                const Eigen::Vector3d& mag_ut) {
  if (!usable(stamp_ns, gyro_rps, mag_ut)) {
    return finish(HardIronStep::kRejectedInput);  // nothing kept: the next step's rate spans it
  }
  // Orientation from the gyro (trapezoidal rate), body to an arbitrary fixed frame; a gap is
  // found by the update below (the orientation across it is then not used).
  const double dt = have_w_ ? static_cast<double>(stamp_ns - last_w_ns_) * 1e-9 : 0.0;
  const Eigen::Vector3d rot = 0.5 * (last_w_ + gyro_rps) * dt;
  const double angle = rot.norm();
  if (dt > 0.0 && dt <= p_.max_dt_s && angle > 0.0) {
    q_ = (q_ * Eigen::Quaterniond(Eigen::AngleAxisd(angle, rot / angle))).normalized();
  }
  have_w_ = true;
  last_w_ns_ = stamp_ns;
  last_w_ = gyro_rps;
  return update(stamp_ns, q_.toRotationMatrix(), gyro_rps, mag_ut);
}

HardIronStep HardIronEstimator::start_grid(int64_t stamp_ns, const Eigen::Matrix3d& r_body,
                                           const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& mag_ut) {
  const bool gap = have_last_;
  if (!r_body.allFinite()) {
    return HardIronStep::kRejectedInput;
  }
  have_last_ = true;
  last_ns_ = stamp_ns;
  have_start_ = false;
  have_before_ = false;
  clear_field();  // the frame across a gap is not known
  prev_ = {stamp_ns, mag_ut, 0.0, r_body};
  int64_t q = stamp_ns / lag_ns_;  // the first multiple of lag_s at or after this stamp
  if (q * lag_ns_ < stamp_ns) {
    ++q;
  }
  next_grid_ns_ = q * lag_ns_;
  if (next_grid_ns_ == stamp_ns) {
    start_ = {stamp_ns, mag_ut, reading_var(gyro_rps, mag_ut), r_body};
    have_start_ = true;
    next_grid_ns_ += lag_ns_;
  }
  return gap ? HardIronStep::kGap : HardIronStep::kWarmingUp;
}

const HardIronReport& HardIronEstimator::update(int64_t stamp_ns, const Eigen::Matrix3d& r_body,
                                                const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& mag_ut,
                                                bool at_rest) {
  if (!usable(stamp_ns, gyro_rps, mag_ut)) {
    return finish(HardIronStep::kRejectedInput);
  }
  const double dt = have_last_ ? static_cast<double>(stamp_ns - last_ns_) * 1e-9 : 0.0;
  if (!have_last_ || !(dt > 0.0) || dt > p_.max_dt_s) {
    return finish(start_grid(stamp_ns, r_body, gyro_rps, mag_ut));
  }
  last_ns_ = stamp_ns;
  if (stamp_ns < next_grid_ns_) {
    prev_.stamp_ns = stamp_ns;  // the per-sample path: the last sample kept, nothing else done
    prev_.m = mag_ut;
    prev_.r = r_body;
    return finish(HardIronStep::kInterval);
  }
  if (!r_body.allFinite() || !prev_.r.allFinite()) {
    return finish(HardIronStep::kRejectedInput);  // the caller's orientation, used only here
  }
  // The reading at the grid instant (a multiple of lag_s), interpolated between the last two
  // samples: the same instants and, for a linearly resampled stream, the same readings at any
  // sample rate (the pairs compared do not depend on where the samples fall).
  const int64_t g = next_grid_ns_;
  const double f = static_cast<double>(g - prev_.stamp_ns) / static_cast<double>(stamp_ns - prev_.stamp_ns);
  const Eigen::Quaterniond q_prev = Eigen::Quaterniond(prev_.r).normalized();
  const Eigen::Quaterniond q_now = Eigen::Quaterniond(r_body).normalized();
  const Eigen::Vector3d m_g = prev_.m + f * (mag_ut - prev_.m);
  const Entry k{g, m_g, reading_var(gyro_rps, m_g), q_prev.slerp(f, q_now).toRotationMatrix()};
  prev_ = {stamp_ns, mag_ut, 0.0, r_body};
  // the next grid instant after this sample (lag_s shorter than a step: the instants between skipped)
  next_grid_ns_ = g + ((stamp_ns - g) / lag_ns_ + 1) * lag_ns_;
  if (!have_start_) {
    start_ = k;
    shared_.setZero();  // its noise is in no comparison used yet
    have_start_ = true;
    return finish(HardIronStep::kInterval);
  }
  // Comparisons do not overlap: the readings between j and k are not used, k starts the next
  // interval, so each reading enters at most two comparisons (as the later, then as the earlier one)
  // and the model errors that persist over an interval are not counted many times over.
  const Entry j = start_;
  start_ = k;
  // the reading before j, if one is (kept for the steps only: step_detection)
  const bool have_i = p_.step_detection && have_before_;
  if (p_.step_detection) {
    std::swap(before_, start_before_);
    before_ = j;
    have_before_ = true;
  }
  const Entry& i = start_before_;
  const double interval_s = static_cast<double>(k.stamp_ns - j.stamp_ns) * 1e-9;
  // E[(b_hat - b) n_j^T] (k's noise is in b_hat once this comparison is used)
  const Eigen::Matrix3d shared = std::exchange(shared_, Eigen::Matrix3d::Zero());
  add_walk(interval_s);
  // R_k^T R_j, made a rotation again (the caller's orientation is renormalised only now and then)
  const Eigen::Quaterniond rel = Eigen::Quaterniond(Eigen::Matrix3d(k.r.transpose() * j.r)).normalized();
  report_.rotation_rad = Eigen::AngleAxisd(rel).angle();
  const Eigen::Matrix3d C = rel.toRotationMatrix();
  const Eigen::Matrix3d H = Eigen::Matrix3d::Identity() - C;
  const Eigen::Vector3d y = k.m - C * j.m;
  const Eigen::Vector3d r = y - H * b_;
  // Both readings carry their own variance per axis: cov(m_k - C m_j) = (var_k + var_j) I.
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity() * (k.var_ut2 + j.var_ut2);
  const Eigen::Matrix3d S = H * P_ * H.transpose() + R;
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(S);
  const double nis = r.dot(ldlt.solve(r));
  start_.fitted = nis <= p_.gate_chi2;  // k's: a later candidate may start from it only if it fitted
  if (track_steps(have_i ? &i : nullptr, j, k, y, C, nis, at_rest)) {
    return finish(HardIronStep::kStep);
  }
  // whether the offset is gone is judged at every grid reading, the body turning or not
  if (removed(k.r, k.m, k.var_ut2, interval_s)) {
    reopen(true);  // the readings fit no offset better than the estimate, beyond chance: the magnet is gone
    return finish(HardIronStep::kReset);
  }
  if (report_.rotation_rad < p_.min_rotation_rad) {
    return finish(HardIronStep::kNotEnoughRotation);
  }
  report_.nis = nis;
  if (step_refuted(nis)) {
    return finish(HardIronStep::kGated);
  }
  consistency(j.m, k.m, interval_s);
  if (!(report_.nis <= p_.gate_chi2)) {
    refused_s_ += interval_s;
    if (refused_s_ >= p_.reset_after_s) {
      reopen(false);
      return finish(HardIronStep::kReset);
    }
    return finish(HardIronStep::kGated);
  }
  refused_s_ = 0.0;
  correct(H, r, R, ldlt);
  track_error(H, C, {k.var_ut2, j.var_ut2, nis, interval_s}, shared);
  return finish(HardIronStep::kUpdated);
}

bool HardIronEstimator::track_steps(const Entry* before, const Entry& j, const Entry& k, const Eigen::Vector3d& y,
                                    const Eigen::Matrix3d& c, double nis, bool at_rest) {
  if (!p_.step_detection || at_rest) {  // at rest the caller's own test judges a moved field
    have_step_ = false;
    return false;
  }
  if (have_step_) {
    return step_confirmed(k);  // a candidate being followed keeps its earlier reading
  }
  step_candidate(before, j, k, y, c, nis);
  return false;
}

bool HardIronEstimator::step_refuted(double nis) {
  // the first comparison that turns after a step judges it: a field that moved with the world (a
  // magnet near the sensor, not on it) does not turn with the body, and the step is undone
  if (!step_provisional_) {
    return false;
  }
  step_provisional_ = false;
  if (nis <= p_.gate_chi2) {
    return false;
  }
  b_ = step_undo_b_;
  P_ = step_undo_p_;
  restart_after_step();
  return true;
}

void HardIronEstimator::step_candidate(const Entry* before, const Entry& j, const Entry& k,
                                       const Eigen::Vector3d& y, const Eigen::Matrix3d& c, double nis) {
  // A comparison the estimate does not fit, the body turning or not, starts a step candidate from
  // its earlier reading j (the last one that fitted): if the offset stepped after j (b_old -> b_new,
  // b_hat = b_old), r = b_new - b_old + n_k - C n_j whatever C; the next readings tell
  // (step_confirmed).
  if (!(nis <= p_.gate_chi2)) {
    if (j.fitted) {  // else j did not fit the reading before it either: no reading to measure from
      start_candidate(j, k, y, c);
    }
    return;
  }
  // the same over the two intervals before k (once per comparison: its cost is a comparison's)
  if (before == nullptr || !before->fitted || k.stamp_ns - before->stamp_ns > 2 * lag_ns_) {
    return;
  }
  const Eigen::Matrix3d c2 = turn_between(k, *before);
  const Eigen::Vector3d y2 = k.m - c2 * before->m;
  if (!fits(c2, y2, k.var_ut2 + before->var_ut2)) {
    start_candidate(*before, k, y2, c2);
  }
}

void HardIronEstimator::start_candidate(const Entry& from, const Entry& k, const Eigen::Vector3d& y,
                                        const Eigen::Matrix3d& c) {
  have_step_ = true;
  step_from_ = from;
  step_y_ = y;
  step_c_ = c;
  step_var_k_ = k.var_ut2;
}

Eigen::Matrix3d HardIronEstimator::turn_between(const Entry& later, const Entry& earlier) {
  // R_k^T R_j, made a rotation again (the caller's orientation is renormalised only now and then)
  return Eigen::Quaterniond(Eigen::Matrix3d(later.r.transpose() * earlier.r)).normalized().toRotationMatrix();
}

bool HardIronEstimator::fits(const Eigen::Matrix3d& c, const Eigen::Vector3d& y, double var_ut2) const {
  const Eigen::Matrix3d h = Eigen::Matrix3d::Identity() - c;
  const Eigen::Vector3d r = y - h * b_;
  Eigen::Matrix3d s = h * P_ * h.transpose();
  s.diagonal().array() += var_ut2;
  return r.dot(s.ldlt().solve(r)) <= p_.gate_chi2;
}

bool HardIronEstimator::step_confirmed(const Entry& k) {
  if (!have_step_) {
    return false;
  }
  have_step_ = false;
  const Entry& j = step_from_;
  if (k.stamp_ns - j.stamp_ns > kStepReadings * lag_ns_) {
    return false;  // the field kept moving (or a gap): no step it settled after
  }
  // The step is measured from the offset the readings were used with: the estimate where one is
  // (applied, or present and not yet removable), else none: the raw readings were what the caller
  // took as the Earth's field, whatever offset they held, and the step is relative to them (b_ref
  // exact). With b_ref, r = y - (I - C) b_ref = step + (I - C) (b_old - b_ref) + n_k - C n_j.
  const bool raw = !report_.present;
  const Eigen::Vector3d b_ref = raw ? Eigen::Vector3d::Zero() : b_;
  // k against the candidate's earlier reading j: a step that stayed gives r2 = r1 up to the later
  // readings' noise and what the two rotations make of b_ref's error and j's noise, r2 - r1 =
  // n_k2 - n_k + (C1 - C2) (b_old - b_ref + n_j); a transient (a tap, a magnet passing by) or a
  // field that keeps moving does not.
  const Eigen::Matrix3d c2 = turn_between(k, j);
  const Eigen::Matrix3d& c1 = step_c_;
  const Eigen::Vector3d y2 = k.m - c2 * j.m;
  const Eigen::Vector3d r1 = step_y_ - b_ref + c1 * b_ref;
  const Eigen::Vector3d r2 = y2 - b_ref + c2 * b_ref;
  // k fits the estimate against j (the field came back: a tap, a magnet passing by, a lone
  // outlier): no step
  if (fits(c2, y2, k.var_ut2 + j.var_ut2)) {
    return false;
  }
  const Eigen::Matrix3d dc = c1 - c2;
  Eigen::Matrix3d pj = raw ? Eigen::Matrix3d::Zero() : P_;
  pj.diagonal().array() += j.var_ut2;
  Eigen::Matrix3d s = dc * pj * dc.transpose();
  s.diagonal().array() += k.var_ut2 + step_var_k_;
  const Eigen::Vector3d d = r2 - r1;
  if (!(d.dot(s.ldlt().solve(d)) <= p_.gate_chi2)) {
    // not settled yet (a reading taken while the offset changed, a magnet on its way): k is the
    // candidate's later reading now, j stays the last reading before the change
    start_candidate(j, k, y2, c2);
    return false;
  }
  // b_ref + the step's mean; its error: -(C1 + C2) / 2 (b_old - b_ref) where b_ref is the estimate
  // (none where the readings were used raw), and the readings' noise
  // (n_j once, the two later readings' averaged)
  const Eigen::Matrix3d p_undo = P_;
  const Eigen::Matrix3d cm = 0.5 * (c1 + c2);
  if (raw) {
    P_.setZero();
  } else {
    P_ = cm * P_ * cm.transpose();
  }
  P_.diagonal().array() += j.var_ut2 + 0.25 * (k.var_ut2 + step_var_k_);
  P_ = 0.5 * (P_ + P_.transpose());
  step_undo_b_ = b_;
  step_undo_p_ = p_undo;
  step_provisional_ = true;
  b_ = b_ref + 0.5 * (r1 + r2);
  refused_s_ = 0.0;
  restart_after_step();
  return true;
}

void HardIronEstimator::restart_after_step() {
  P_err_ = P_;
  shared_.setZero();
  clear_field();  // f(b) holds for one offset over the window: it changed
  // whether removing b makes |m| more constant is judged again from the comparisons that turn
  raw_change2_ = 0.0;
  cor_change2_ = 0.0;
  change_weight_ = 0.0;
  refresh();
}

void HardIronEstimator::correct(const Eigen::Matrix3d& h, const Eigen::Vector3d& r, const Eigen::Matrix3d& noise,
                                const Eigen::LDLT<Eigen::Matrix3d>& s_ldlt) {
  const Eigen::Matrix3d K = s_ldlt.solve(h * P_).transpose();  // P H^T S^-1 (P, S symmetric)
  b_ += K * r;
  const Eigen::Matrix3d IKH = Eigen::Matrix3d::Identity() - K * h;
  P_ = IKH * P_ * IKH.transpose() + K * noise * K.transpose();
  P_ = 0.5 * (P_ + P_.transpose());
  gain_ = K;
  refresh();
}

void HardIronEstimator::add_walk(double interval_s) {
  // b's random walk over the interval, added once per comparison (P is constant in between)
  const double walk = p_.walk_ut_per_sqrt_s * p_.walk_ut_per_sqrt_s * interval_s;
  P_.diagonal().array() += walk;
  P_err_.diagonal().array() += walk;
  refresh();
}

void HardIronEstimator::track_error(const Eigen::Matrix3d& h, const Eigen::Matrix3d& c, const Comparison& z,
                                    const Eigen::Matrix3d& shared) {
  if (p_.noise_tau_s > 0.0) {  // the noise the accepted comparisons show (noise_ratio)
    const double keep = std::exp(-z.interval_s / p_.noise_tau_s);
    nis_sum_ = keep * nis_sum_ + z.nis;
    nis_w_ = keep * nis_w_ + 1.0;
  }
  // The comparison's noise is n_k - C n_j, and n_j was the later reading of the last comparison
  // used: b_hat's error e and that noise are correlated (shared), which P, taking each comparison's
  // noise as its own, leaves out. With the same gain K: e' = (I - K H) e + K n_k - K C n_j, each
  // reading's variance the model's times noise_ratio() (the comparisons' NIS), so
  //   P_err' = A P_err A^T + K (v_k I + v_j C C^T) K^T - A X C^T K^T - K C X^T A^T,  A = I - K H,
  // X = E[e n_j^T] = shared; then E[e' n_k^T] = K v_k (k's noise, shared with the next comparison).
  const double rho = noise_ratio();
  const Eigen::Matrix3d& k = gain_;
  const Eigen::Matrix3d a = Eigen::Matrix3d::Identity() - k * h;
  const Eigen::Matrix3d cross = a * shared * c.transpose() * k.transpose();
  P_err_ = a * P_err_ * a.transpose() + rho * (z.var_k + z.var_j) * (k * k.transpose()) - cross - cross.transpose();
  P_err_ = 0.5 * (P_err_ + P_err_.transpose());
  shared_ = rho * z.var_k * k;
}

void HardIronEstimator::reopen(bool zero) {
  refused_s_ = 0.0;
  have_step_ = false;
  step_provisional_ = false;
  clear_field();  // f(b) = mean(z) - mean(R) b holds for one offset over the window: it changed
  if (zero) {
    b_.setZero();
  }
  P_ = Eigen::Matrix3d::Identity() * (p_.prior_sigma_ut * p_.prior_sigma_ut);
  P_err_ = P_;  // (the noise seen stays: the sensor's, not the offset's)
  shared_.setZero();
  refresh();
}

}  // namespace poise
