// Running an AttitudeFilter over a BROAD trial and tabulating benchmark results.
#pragma once

#include "poise/core/attitude_filter.h"
#include "poise/core/consistency.h"
#include "poise/eval/broad.h"

#include <iosfwd>
#include <string>
#include <vector>

namespace poise::eval {

/// Optional second interface of a filter that also consumes inputs derived from the trial (e.g.
/// the selective EKF's vision synthesised from the reference): run_filter() calls begin_trial()
/// right after reset(); the filter then feeds itself per update() (sample k = k-th update).
class TrialInputs {
 public:
  virtual ~TrialInputs() = default;
  virtual void begin_trial(const BroadTrial& trial) = 0;
};

/// Runs `filter` (reset first) over every sample of `trial`, first to last; returns one
/// q_world_body per input sample (identity before the filter is initialised). ESTIMATED, when
/// given, receives the number of samples after which the filter was initialised (0: it rejected
/// every sample, and the identities are no estimate to score).
std::vector<Eigen::Quaterniond> run_filter(AttitudeFilter& filter, const BroadTrial& trial,
                                           size_t* estimated = nullptr);

/// What a filter published after each sample of a trial: q_world_body and its covariance
/// (AttitudeFilter::attitude_covariance(); all NaN where it published none).
struct TrialEstimates {
  std::vector<Eigen::Quaterniond> q;
  std::vector<Eigen::Matrix3d> cov;
};
/// run_filter() keeping the covariances too.
TrialEstimates run_filter_estimates(AttitudeFilter& filter, const BroadTrial& trial, size_t* estimated = nullptr);

/// Writes `t_s,qw,qx,qy,qz`, one row per sample.
void write_quaternion_csv(const std::string& path, const std::vector<Eigen::Quaterniond>& q, double rate_hz);
/// Writes `t_s,qw,qx,qy,qz,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz`, one row per sample: the
/// published covariance of the world-frame rotation vector of q_true (x) q_est^-1, rad^2 (the
/// upper triangle; `nan` where the filter published none).
void write_estimate_csv(const std::string& path, const TrialEstimates& e, double rate_hz);

/// NEES of each scored sample (movement and a valid reference, as broad_errors()) against the
/// published covariance.
NeesSummary broad_consistency(const TrialEstimates& e, const BroadTrial& trial);

struct TrialResult {
  std::string stem;
  int number = 0;
  bool disturbed = false;
  TrialErrors errors;
  NeesSummary nees;  ///< empty when not computed (print_table then shows "-")
};

/// Prints the per-trial table and the means for undisturbed (01-23), disturbed (24-39) and all;
/// a trial without scorable samples shows "-" and is named as excluded. Two consistency columns
/// follow: the median NEES and the % of scored samples inside the 95 % ellipsoid (NEES <= 7.815),
/// per trial and over the pooled samples of each group ("-" without a covariance).
void print_table(std::ostream& os, const std::string& filter_name, const std::vector<TrialResult>& results);

/// `value` right-aligned in `width` with 3 decimals, or "-" when the trial has no figure.
std::string format_trial_figure(const TrialErrors& e, double value, int width);
/// A mean over `n` trials, right-aligned in `width`, 3 decimals; "-" over no trial or when not
/// finite (never a 0.000 mean of nothing, never nan).
std::string format_mean_figure(double value, int n, int width);
/// The two consistency columns (median NEES width 10, % inside the 95 % ellipsoid width 8);
/// "-" in both over no sample with a covariance.
std::string format_consistency(const NeesSummary& nees);

/// Plain means of the per-trial figures. Trials without scorable samples have no figure: they
/// are left out of every mean and counted (never averaged in as 0).
struct GroupMeans {
  TrialErrors undisturbed, disturbed, all;
  int n_undisturbed = 0, n_disturbed = 0;  ///< scored trials per group
  std::vector<std::string> unscored;       ///< stems of the trials left out
};
GroupMeans group_means(const std::vector<TrialResult>& results);

}  // namespace poise::eval
