// Online estimate of a hard-iron offset: a field source fixed to the sensor (a magnet attached to
// it, a headset's own speaker magnets) adds a constant body-frame vector b to every reading,
// m_body = R^T m_world + b. The gyro says how the body turned between two readings, so with the
// world field constant, m_k - b = C (m_j - b), C = R_k^T R_j: the measurement
// y = m_k - C m_j = (I - C) b is linear in b and needs no sphere coverage, only rotation
// (b along the rotation axis is unobservable while the body turns about that axis alone; the
// covariance says so). A Kalman filter on b (3 states, random walk) with a chi-square gate; an
// offset changes in steps (a magnet attached or removed), so innovations refused for
// `reset_after_s` in a row reopen the covariance to the prior and b is learnt again.
// Pure core: no clock, no I/O; stamps in ns, field in uT, rates in rad/s.
#pragma once

#include "poise/core/types.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstddef>
#include <cstdint>

namespace poise {

struct HardIronParams {
  double prior_sigma_ut = 100.0;      ///< initial (and after a reset) 1-sigma of each axis of b, uT
  double noise_ut = 1.5;              ///< 1-sigma per axis of one reading against the model, uT
  /// Uncertainty of the reading's instant against the gyro's, s: a reading taken while the body
  /// turns at |w| is off by |w| timing_s |m| (added to noise_ut in quadrature, per reading)
  double timing_s = 0.002;
  double walk_ut_per_sqrt_s = 0.05;   ///< random walk of b (slow drift: temperature), uT/sqrt(s)
  double lag_s = 0.25;                ///< interval between the two readings compared, s (0.001-100)
  double min_rotation_rad = 0.2;      ///< least rotation over lag_s for an update, rad
  double gate_chi2 = 16.27;           ///< innovation gate (3 dof, 99.9 %)
  double reset_after_s = 0.5;         ///< refused innovations this long in a row: b learnt again, s
  double converged_sigma_ut = 2.0;    ///< every axis' sigma below this: the estimate is used, uT
  /// |b| at or below this is not applied, uT: on BROAD's undisturbed trials the estimate reaches
  /// 2-4 uT where the sensor moves through a non-uniform field (translation trials), which a
  /// correction turns into heading error (the horizontal field is 16 uT: 1 uT is up to 3.6 deg).
  /// Chosen on BROAD from {0, 2, 3, 5, 8}: 5 in every leave-one-trial-out fold but one (8), see
  /// docs/ESTIMATORS.md "Hard-iron offset".
  double min_applied_ut = 5.0;
  /// The offset is applied only while removing it makes the field's magnitude more constant over
  /// rotation than the raw readings' (a body-fixed offset must: |R^T m_world + b| varies with R,
  /// |R^T m_world| does not). Each comparison with enough rotation adds the squared change of
  /// |m| and of |m - b| (b: the estimate then) between its two readings; both sums forget with
  /// this time constant, s (0 = no check). A field that varies in space (a magnet near the sensor,
  /// not on it) fits an offset, but removing it makes the magnitude vary where it did not.
  double consistency_tau_s = 5.0;
  /// The offset is taken as gone (b learnt again, as after reset_after_s) once the evidence that
  /// the readings carry no offset at all outweighs the estimate by this log-likelihood ratio
  /// (0 = no test). Each grid reading k (every lag_s) is seen from the caller's gyro frame,
  /// z = R_k m_k; the field there, f, is followed over removed_tau_s as sums of z and R_k, so that
  /// f(b) = mean(z) - mean(R) b holds for any b (the estimate's later changes included). While the
  /// estimate is present, "no offset" predicts z = f(b_hat), "the estimate" z - R_k b_hat = f(b_hat):
  /// the two differ by R_k b_hat, |b| whatever the body's rate (a test of readings lag_s apart sees
  /// only (I - C) b, the rotation over lag_s: 15-20 s for 8 uT in slow hand-held motion). Each
  /// reading that either hypothesis fits (normalised residual <= gate_chi2) adds
  /// log p(z | no offset) - log p(z | b ~ N(b_hat, P)) to a sum held at or above zero (Page's
  /// CUSUM); the chance that the sum ever reaches h while the offset is still there is at most
  /// e^-h (Wald); 6.9: 1e-3.
  double removed_log_lr = 6.9;
  /// The time constant over which the field seen from the gyro frame is taken as constant for the
  /// removal test, s: the reading's noise averages over it (its variance in the mean is added), the
  /// frame's drift and the field's variation in space must stay within the noise over it. The
  /// same window as consistency_tau_s (recent comparisons), not chosen on data.
  double removed_tau_s = 5.0;
  /// error_covariance() only (published covariances; the estimate's gains, gate and convergence
  /// read covariance()): the reading noise the accepted comparisons show, their NIS / 3 averaged
  /// over this, s, scales noise_ut's variance in b's error covariance. The same window as
  /// consistency_tau_s (recent comparisons), not chosen on data. 0 = noise_ut's, as covariance().
  double noise_tau_s = 5.0;
  /// Steps of the offset (a magnet put on, moved or taken off) are taken from the readings whatever
  /// the rotation (HardIronStep::kStep): a comparison the estimate does not fit, confirmed by the
  /// next reading against the same earlier one. Off by default (an offset is learnt from rotation
  /// only): a field that changes while the sensor moves without turning is taken as a step whether
  /// it turns with the body or not, and only a turn tells them apart, so a magnet brought near is
  /// removed as if it were on the sensor (the demo's tour: parallel KF 0.34 -> 18.7 deg,
  /// docs/ESTIMATORS.md "Steps of the offset"). On where the disturbances are the sensor's own (a
  /// motor, a speaker, a magnet fixed to it).
  bool step_detection = false;
  double max_dt_s = 0.1;              ///< a longer gap between samples restarts the comparison, s
  double max_mag_ut = 5000.0;         ///< |m| above this (or non-finite) is refused, uT
  double max_gyro_rps = 100.0;        ///< |w| above this (or non-finite) is refused, rad/s
  /// Throws std::invalid_argument "<filter> parameter <key> must be ..." on a bad value (`filter`:
  /// how the caller's messages name this section, e.g. "parallel_kf hard_iron_estimator").
  void validate(const char* filter = "hard_iron") const;
  /// Reads the keys above (same names) with a YamlParamReader (poise/core/yaml_params.h; a
  /// template, so this header needs no yaml-cpp): the filters' `hard_iron_estimator:` sections.
  template <typename Reader>
  void read(Reader& r) {
    r.get("prior_sigma_ut", prior_sigma_ut);
    r.get("noise_ut", noise_ut);
    r.get("timing_s", timing_s);
    r.get("walk_ut_per_sqrt_s", walk_ut_per_sqrt_s);
    r.get("lag_s", lag_s);
    r.get("min_rotation_rad", min_rotation_rad);
    r.get("gate_chi2", gate_chi2);
    r.get("reset_after_s", reset_after_s);
    r.get("converged_sigma_ut", converged_sigma_ut);
    r.get("min_applied_ut", min_applied_ut);
    r.get("consistency_tau_s", consistency_tau_s);
    r.get("removed_log_lr", removed_log_lr);
    r.get("removed_tau_s", removed_tau_s);
    r.get("noise_tau_s", noise_tau_s);
    r.get("max_dt_s", max_dt_s);
    r.get("max_mag_ut", max_mag_ut);
    r.get("max_gyro_rps", max_gyro_rps);
    r.get("step_detection", step_detection);
  }
};

/// Why the last sample did or did not update the estimate.
enum class HardIronStep {
  kUpdated,          ///< the comparison was used
  kWarmingUp,        ///< the first reading (start or after reset()): nothing to compare yet
  kInterval,         ///< the last comparison's reading is not lag_s old yet (non-overlapping comparisons)
  kNotEnoughRotation,///< rotation over lag_s below min_rotation_rad: b not observable
  kGated,            ///< innovation refused by the chi-square gate
  kReset,            ///< refused for reset_after_s: the covariance reopened (offset changed)
  /// the offset stepped (a magnet attached, moved or taken off): a comparison the estimate did not
  /// fit, confirmed by the next reading against the same earlier one; b moved by the step
  kStep,
  kGap,              ///< stamp gap beyond max_dt_s (or not increasing): the interval starts again
  kRejectedInput,    ///< non-finite or out-of-range reading or stamp (< 0, > kMaxStampNs): nothing used, counted
  kNoMagnetometer,   ///< the sample has no magnetometer (or no gyro)
  kCount,            ///< number of reasons (not a reason)
};
const char* to_string(HardIronStep s);

struct HardIronReport {
  HardIronStep step = HardIronStep::kWarmingUp;
  double nis = 0.0;          ///< normalised innovation squared of the last comparison
  double rotation_rad = 0.0; ///< rotation over the last comparison's interval
  bool converged = false;    ///< every axis' sigma < converged_sigma_ut
  /// rms change of |m| (raw) and of |m - b| between the two readings of the recent comparisons, uT
  /// (consistency_tau_s); the offset is consistent when the corrected one is the smaller
  double raw_norm_change_ut = 0.0;
  double corrected_norm_change_ut = 0.0;
  bool consistent = false;
  /// An offset is there: |b| > min_applied_ut, consistent, and converged or b far from zero
  /// against its covariance (b^T P^-1 b > gate_chi2). Present but not converged: the raw reading
  /// carries an offset that cannot be removed yet.
  bool present = false;
  double removed_llr = 0.0;  ///< the CUSUM of the log-likelihood ratio for "no offset" (removed_log_lr)
  /// the last judged grid reading's normalised residuals against the field followed in the gyro
  /// frame (removed_tau_s): under "no offset" and under the estimate (3 dof each)
  double removed_nis_none = 0.0;
  double removed_nis_estimate = 0.0;
  /// per step reason (indexed by HardIronStep), since construction/reset: an array, not a map,
  /// so the per-sample path of a filter that carries the estimator does no lookup
  std::array<uint64_t, static_cast<size_t>(HardIronStep::kCount)> counts{};
  [[nodiscard]] uint64_t count(HardIronStep s) const { return counts[static_cast<size_t>(s)]; }
  /// Whether the estimate has judged the reading's offset: one present (pending, then removed), or
  /// converged and the last comparison accepted (an estimate converged before the field moved is
  /// refused by the new readings, then learnt again). FieldMovedAtRest::hold releases on it.
  [[nodiscard]] bool judged() const { return present || (converged && step == HardIronStep::kUpdated); }
};

class HardIronEstimator {
 public:
  explicit HardIronEstimator(const HardIronParams& p = {});
  /// Feeds one sample; returns the report of this step. The rotation between samples is
  /// integrated here from the gyro (trapezoidal rate): for a caller without its own propagation.
  const HardIronReport& update(const ImuSample& s);
  /// The same from the parts a filter has at hand (its bias-corrected gyro, the raw reading).
  const HardIronReport& update(int64_t stamp_ns, const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& mag_ut);
  /// The same for a filter that already propagates the gyro: `r_body` is its gyro-only orientation
  /// at this sample (body -> any frame fixed over lag_s, e.g. the parallel KF's R_ib), so the gyro
  /// is not integrated a second time here; the rotation between two readings is r_k^T r_j, taken
  /// once per comparison. `gyro_rps` only sizes the reading's timing variance.
  /// `at_rest`: the caller's rest detector says the body is at rest; no step of the offset is taken
  /// from readings at rest (kStep): a field that moves there may as well be a magnet brought near,
  /// and the caller's own test holds it (FieldMovedAtRest) until a turn has judged it.
  const HardIronReport& update(int64_t stamp_ns, const Eigen::Matrix3d& r_body, const Eigen::Vector3d& gyro_rps,
                               const Eigen::Vector3d& mag_ut, bool at_rest = false);
  /// The body-frame offset estimate, uT, and its covariance, uT^2.
  [[nodiscard]] const Eigen::Vector3d& offset_ut() const { return b_; }
  [[nodiscard]] const Eigen::Matrix3d& covariance() const { return P_; }
  [[nodiscard]] Eigen::Vector3d sigma_ut() const { return P_.diagonal().cwiseSqrt(); }
  /// b's error covariance, uT^2: the same gains, walk and prior as covariance(), with the
  /// comparisons' noise as it is: a reading is the later of one comparison and the earlier of the
  /// next, so their noises are correlated (covariance() takes them as independent), and each
  /// reading's variance is noise_ratio() times the model's (noise_tau_s). What a published
  /// covariance should read; the estimate never does.
  [[nodiscard]] const Eigen::Matrix3d& error_covariance() const { return P_err_; }
  /// The accepted comparisons' NIS / 3 averaged over noise_tau_s (1 before any, or with
  /// noise_tau_s 0): about 1 while b is uncertain whatever the noise, the reading noise's variance
  /// over the model's once b is known.
  [[nodiscard]] double noise_ratio() const { return nis_w_ > 0.0 ? nis_sum_ / (3.0 * nis_w_) : 1.0; }
  [[nodiscard]] bool converged() const { return report_.converged; }
  /// Whether corrected() removes the offset: converged, |b| > min_applied_ut and consistent (the
  /// corrected field's magnitude changes less over rotation than the raw one's).
  [[nodiscard]] bool applied() const { return applied_; }
  /// An offset is in the readings but not known well enough to remove (present, not converged):
  /// the raw reading is not the Earth's field and cannot be corrected yet.
  [[nodiscard]] bool pending() const { return report_.present && !applied_; }
  /// The reading with the offset removed when applied(), unchanged otherwise.
  [[nodiscard]] Eigen::Vector3d corrected(const Eigen::Vector3d& m_ut) const { return applied() ? Eigen::Vector3d(m_ut - b_) : m_ut; }
  [[nodiscard]] const HardIronReport& report() const { return report_; }
  [[nodiscard]] const HardIronParams& params() const { return p_; }
  void reset();

 private:
  struct Entry {
    int64_t stamp_ns = 0;
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    double var_ut2 = 0.0;  ///< per-axis variance of this reading against the model
    Eigen::Matrix3d r = Eigen::Matrix3d::Identity();  ///< the caller's orientation at the reading
    /// the estimate fitted its comparison with the reading before it (or none was made): a reading a
    /// step candidate may start from
    bool fitted = true;
  };
  const HardIronReport& finish(HardIronStep s);
  /// Adds one comparison's |m| and |m - b| changes (consistency_tau_s) and refreshes.
  void consistency(const Eigen::Vector3d& m_j, const Eigen::Vector3d& m_k, double interval_s);
  void refresh();  ///< converged and applied from b_ and P_ (called where they change, not per sample)
  /// Adds grid reading k's log-likelihood ratio of "no offset" against the estimate, judged
  /// against the field followed in the gyro frame (removed_log_lr, removed_tau_s), then follows
  /// the field with k; true when the sum reached the threshold (the offset is gone).
  bool removed(const Eigen::Matrix3d& r_k, const Eigen::Vector3d& m_k, double var_ut2, double interval_s);
  void clear_field();  ///< the field followed in the gyro frame starts again (removed_tau_s)
  /// Whether reading k confirms the step candidate: compared with the candidate's earlier reading
  /// it shows the same step as the candidate's later reading (the field settled and stayed); then b
  /// moves by it and P takes its noise. Not yet settled, k becomes the later reading, for at most
  /// kStepReadings grid intervals from the earlier one.
  bool step_confirmed(const Entry& k);
  /// Starts a step candidate when the estimate does not fit reading k against j (the comparison's
  /// NIS, `nis`) or against the reading before j (a step split between two intervals: a change
  /// over a few samples that straddles the grid instant j, a magnet put on by hand).
  void step_candidate(const Entry* before, const Entry& j, const Entry& k, const Eigen::Vector3d& y,
                      const Eigen::Matrix3d& c, double nis);
  /// A step candidate from reading `from` (the last that fitted) to k: y = m_k - C m_from, C.
  void start_candidate(const Entry& from, const Entry& k, const Eigen::Vector3d& y, const Eigen::Matrix3d& c);
  /// R_later^T R_earlier, made a rotation again (the caller's orientation is renormalised only now
  /// and then).
  static Eigen::Matrix3d turn_between(const Entry& later, const Entry& earlier);
  /// Whether the estimate fits a comparison y = m_k - C m_j of two readings whose variances per
  /// axis sum to var_ut2 (its NIS within gate_chi2).
  [[nodiscard]] bool fits(const Eigen::Matrix3d& c, const Eigen::Vector3d& y, double var_ut2) const;
  /// The first sample, or the first after a gap: the comparisons start again on the grid of lag_s
  /// from it (kWarmingUp or kGap; kRejectedInput for a non-finite orientation, nothing kept).
  HardIronStep start_grid(int64_t stamp_ns, const Eigen::Matrix3d& r_body, const Eigen::Vector3d& gyro_rps,
                          const Eigen::Vector3d& mag_ut);
  /// The steps of the offset at grid reading k (step_detection, not at rest): the candidate being
  /// followed judged (step_confirmed), else one started (step_candidate); true when a step was taken.
  bool track_steps(const Entry* before, const Entry& j, const Entry& k, const Eigen::Vector3d& y,
                   const Eigen::Matrix3d& c, double nis, bool at_rest);
  /// Whether the first comparison that turns after a step (NIS `nis`) refutes it: then it is undone.
  bool step_refuted(double nis);
  /// After a step taken or undone (b and P set): the error covariance, the field followed in the
  /// gyro frame and the consistency sums start again from them.
  void restart_after_step();
  /// The longest a step candidate is followed, grid intervals (lag_s each) from its earlier reading:
  /// the step plus a reading taken while the offset changed plus the two that agree.
  static constexpr int64_t kStepReadings = 4;
  /// The Kalman update of b and P with one comparison (H = I - C, innovation r, its noise, S's LDLT).
  void correct(const Eigen::Matrix3d& h, const Eigen::Vector3d& r, const Eigen::Matrix3d& noise,
               const Eigen::LDLT<Eigen::Matrix3d>& s_ldlt);
  void add_walk(double interval_s);  ///< b's random walk over one comparison's interval, to both covariances
  struct Comparison {
    double var_k = 0.0;       ///< the later reading's variance per axis (the model's), uT^2
    double var_j = 0.0;       ///< the earlier one's
    double nis = 0.0;         ///< its normalised innovation squared
    double interval_s = 0.0;  ///< between the two readings
  };
  /// error_covariance() through the comparison just used (its gain gain_, H = I - C, and
  /// E[(b_hat - b) n_j^T] before it), after its NIS joins noise_ratio(); shared_ for the next.
  void track_error(const Eigen::Matrix3d& h, const Eigen::Matrix3d& c, const Comparison& z,
                   const Eigen::Matrix3d& shared);
  /// b learnt again: P back to the prior (and b to zero when `zero`: the offset is gone).
  void reopen(bool zero);
  [[nodiscard]] bool usable(int64_t stamp_ns, const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& mag_ut) const;
  [[nodiscard]] double reading_var(const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& mag_ut) const;

  HardIronParams p_;
  int64_t lag_ns_ = 0;  ///< p_.lag_s in ns
  Eigen::Vector3d b_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d P_;
  Entry start_;  ///< the reading that starts the current interval
  Entry before_;  ///< the earlier reading of the last comparison (a step split over two intervals)
  Entry start_before_;  ///< the one before it, during a comparison (swapped with before_, not copied)
  bool have_before_ = false;
  bool have_start_ = false;
  Entry prev_;   ///< the last usable sample (a grid reading is interpolated between it and the next)
  int64_t next_grid_ns_ = 0;  ///< the next instant (a multiple of lag_s) a reading is taken at
  bool have_last_ = false;
  int64_t last_ns_ = 0;
  /// update(stamp, gyro, mag)'s own gyro integration (trapezoidal rate; arbitrary start)
  Eigen::Quaterniond q_ = Eigen::Quaterniond::Identity();
  Eigen::Vector3d last_w_ = Eigen::Vector3d::Zero();
  int64_t last_w_ns_ = 0;
  bool have_w_ = false;
  double refused_s_ = 0.0;  ///< time of consecutive refused comparisons
  /// A step candidate: the earlier reading of the last comparison the estimate did not fit and that
  /// comparison's innovation (the step, if the field stays moved; step_confirmed())
  Entry step_from_;
  Eigen::Vector3d step_y_ = Eigen::Vector3d::Zero();  ///< that comparison's y = m_k - C m_j
  Eigen::Matrix3d step_c_ = Eigen::Matrix3d::Identity();  ///< that comparison's C = R_k^T R_j
  double step_var_k_ = 0.0;
  bool have_step_ = false;
  /// A step taken and not yet judged by a comparison that turned: it is undone (b and P as before
  /// it) if that comparison does not fit
  bool step_provisional_ = false;
  Eigen::Vector3d step_undo_b_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d step_undo_p_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d P_err_;     ///< error_covariance()
  Eigen::Matrix3d gain_ = Eigen::Matrix3d::Zero();    ///< the last comparison's gain K
  Eigen::Matrix3d shared_ = Eigen::Matrix3d::Zero();  ///< E[(b_hat - b) n^T], n the interval's start reading's noise
  double nis_sum_ = 0.0;      ///< forgetting sums of the accepted comparisons' NIS and weights (noise_tau_s)
  double nis_w_ = 0.0;
  double raw_change2_ = 0.0;  ///< forgetting sums of the squared |m| / |m - b| changes, uT^2
  double cor_change2_ = 0.0;
  double change_weight_ = 0.0;  ///< the same sum of the weights (for the rms)
  /// The field followed in the gyro frame (removed_tau_s): forgetting sums of R_k m_k, uT, of
  /// R_k, of the weights and of the squared weights times the reading's variance
  Eigen::Vector3d field_sum_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d frame_sum_ = Eigen::Matrix3d::Zero();
  double field_w_ = 0.0;
  double field_var2_ = 0.0;
  double field_refused_s_ = 0.0;  ///< time of consecutive readings neither hypothesis fits, s (removed_tau_s)
  bool applied_ = false;
  HardIronReport report_;
};

}  // namespace poise
