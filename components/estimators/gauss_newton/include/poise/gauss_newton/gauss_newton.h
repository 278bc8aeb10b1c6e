// Gauss-Newton orientation from one accelerometer + magnetometer sample: the "G-N" baseline of
// paper 000 (its reference [5]) and the IMU quaternion input of the selective EKF (paper 002 eq. 2).
//
// Notation (ESTIMATORS.md section 3)
//   q        q_world_body (ENU world), the unknown.
//   a_n, m_n measured accelerometer and magnetometer, normalised (body frame).
//   u, r     world references: u = e_z (up), r = [0, cos(dip), -sin(dip)] (magnetic north, ENU).
//   e(q)     = [a_n - R(q)^T u ; w_m (m_n - R(q)^T r)]       (6-vector residual)
//   q_{i+1}  = q_i - (J^T J)^-1 J^T e                         (paper 002 eq. 2)
// We parametrise the step multiplicatively, q_{i+1} = q_i exp(delta), so J = d e / d delta =
// -[ [R^T u x] ; w_m [R^T r x] ] (6x3) instead of the 6x4 quaternion Jacobian: the same
// Gauss-Newton iteration without the singular norm direction of the 4-parameter form.
// Iterations start from the previous estimate and stop after max_iterations or when |delta| <
// tolerance_rad. No disturbance compensation (that is why it is the baseline).
// The dip is configured or learnt as the mean measured angle over the first startup_samples.
// Cold start (issue 31; field_verify_s): a field gate (poise/core/field_gate.h, fixed reference,
// no re-acquisition) judges the field against the start-up one, with the accelerometer as up.
// Until it has accepted the field for field_verify_s the reference is provisional: the heading is
// unverified, its published variance that of a heading uniform over +-180 deg, and a gated field
// that stays consistent (an Earth-sized one, see FieldGate) replaces the learnt dip (a start next
// to a magnet learns the magnet's dip, which tilts and turns every later solution). A configured
// dip and field magnitude (or the World Magnetic Model's, seed_field) are verified from the start.
#pragma once

#include "poise/core/attitude.h"
#include "poise/core/attitude_filter.h"
#include "poise/core/field_gate.h"
#include "poise/core/north.h"
#include "poise/core/sample_check.h"
#include "poise/core/source_report.h"
#include "poise/core/state_health.h"
#include "poise/core/types.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <string>

namespace poise {

struct GaussNewtonParams {
  int max_iterations = 5;          ///< per sample (>= 1)
  double tolerance_rad = 1e-7;     ///< stop when the step is smaller, rad
  double mag_weight = 1.0;         ///< w_m: weight of the magnetometer rows (1 = paper)
  double dip_deg = std::nan("");   ///< NaN: learn at start-up; else the configured dip, deg
  int startup_samples = 50;        ///< samples averaged to learn the dip
  /// |m| reference of the cold-start gate, uT; NaN = learnt over its first second. With dip_deg
  /// (both from the World Magnetic Model when a location is known) the reference is verified.
  double field_magnitude_ut = std::nan("");
  /// A learnt field reference is provisional until the gate has accepted the field for this long,
  /// s (the parallel KF's mag_verify_s); 0 = verified when learnt, no re-learning (before).
  double field_verify_s = 5.0;
  SampleLimits limits;             ///< input validation
  /// `use_magnetometer`: auto (default) or true. The solution needs the field in every sample, so
  /// a sample without a magnetometer is refused either way: auto reports its accelerometer rejected
  /// "no_mag" (not counted), true counts it no_magnetometer. false (6-axis) is refused by
  /// validate(): this filter cannot run without a magnetometer.
  MagnetometerUse use_magnetometer = MagnetometerUse::kAuto;
  /// Throws std::invalid_argument naming the key and its range (ParamCheck); `filter` names the
  /// section in messages.
  void validate(const char* filter = "gauss_newton") const;
  /// Reads the keys above but use_magnetometer and limits with a YamlParamReader
  /// (poise/core/yaml_params.h; a template, so this header needs no yaml-cpp): the file's
  /// `gauss_newton:` section, and the selective EKF's (which sets the other two itself).
  template <typename Reader>
  void read(Reader& r) {
    r.get("max_iterations", max_iterations);
    r.get("tolerance_rad", tolerance_rad);
    r.get("mag_weight", mag_weight);
    r.get_nullable("dip_deg", dip_deg);
    r.get("startup_samples", startup_samples);
    r.get_nullable("field_magnitude_ut", field_magnitude_ut);
    r.get("field_verify_s", field_verify_s);
  }
};

/// Loads GaussNewtonParams from a YAML file (keys as the fields, under `gauss_newton:` or at the
/// top level, and use_magnetometer; unknown keys are an error). Throws std::runtime_error with a
/// message naming the file and the key.
GaussNewtonParams load_gauss_newton_params(const std::string& path);

struct GaussNewtonResult {
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();
  int iterations = 0;       ///< iterations run for the last sample
  double residual = 0.0;    ///< |e| after the last iteration (unit-vector units)
  /// J^T J at the solution (J = d e / d delta, body-frame small rotation): the information of
  /// one unit of residual variance, for the covariance
  Eigen::Matrix3d information_body = Eigen::Matrix3d::Identity();
  /// R(q)^T u at the solution: world up in the body frame (the accelerometer rows' direction)
  Eigen::Vector3d up_body = Eigen::Vector3d::UnitZ();
};

/// The residual variance is averaged over this long, s (GaussNewton::attitude_covariance()).
inline constexpr double kResidualTauS = 0.5;
/// Floor of that variance, unit-vector components^2 (1e-3 deg of a direction): keeps the published
/// covariance positive definite on a noise-free sample.
inline constexpr double kMinResidualVar = 3e-10;
/// The accelerometer norm's reference (the gravity the sensor reads) is its mean over this long, s:
/// a device that does not fly away has a bounded vertical velocity, so its vertical external
/// acceleration averages out over seconds; the first samples take the cumulative mean.
inline constexpr double kGravityNormTauS = 10.0;

/// The external-acceleration term of the Gauss-Newton covariance (issue 31). The least-squares
/// covariance sigma^2 (J^T J)^-1 assumes the accelerometer direction's error per component is the
/// residual's sigma^2. The accelerometer norm shows the vertical external acceleration (plus
/// noise): |f| - g ~ a_z. Taken isotropic (each axis as large as the vertical one), the
/// accelerometer direction's error variance per component is var_a = E(|f| - g)^2 / g^2. What
/// exceeds sigma^2 enters through the solution's sensitivity to the accelerometer rows:
/// d delta = -(J^T J)^-1 J_a^T d a, J_a = -[p_u x], J_a^T J_a = I - p_u p_u^T, so
///   P_body += max(0, var_a - sigma^2) (J^T J)^-1 (I - p_u p_u^T) (J^T J)^-1,
/// which carries a tilt about north into the heading by tan(dip) (the field's vertical part).
/// Returns that matrix per unit of excess variance (body frame, rad^2 per unit-vector component^2).
[[nodiscard]] Eigen::Matrix3d accel_direction_sensitivity(const Eigen::Matrix3d& information_body,
                                                          const Eigen::Vector3d& up_body);

/// Everything the Gauss-Newton filter carries from one sample to the next besides its
/// parameters: inspect it, save it, restore it into a filter with the same parameters.
struct GaussNewtonState {
  GaussNewtonResult result;
  bool initialized = false;
  double dip_rad = 0.0;
  double dip_sum_rad = 0.0;  ///< start-up dip learning: sum and count of measured dips
  int dip_n = 0;
  FieldGate gate;  ///< the cold-start gate (field_verify_s): a provisional reference relearnt
  double residual2_lp = 0.0;  ///< |e|^2 low-passed over kResidualTauS (unit-vector units^2)
  double gravity_mps2 = 0.0;  ///< the accelerometer norm's mean over kGravityNormTauS, m/s^2
  int64_t gravity_n = 0;      ///< samples in that mean (cumulative until kGravityNormTauS is reached)
  double norm_dev2_lp = 0.0;  ///< (|f| - gravity)^2 low-passed over kResidualTauS, (m/s^2)^2
  int64_t last_stamp_ns = -1;
  StampAnchor anchor;  ///< time restarts after a stamp jump only when two samples agree
  RejectCounters rejections;
  SourceReport accel{Source::kAccel};
  SourceReport mag{Source::kMag};
  StateHealth health;  ///< resets after a non-finite or non-unit solution (state_health.h)
};

class GaussNewton {
 public:
  explicit GaussNewton(const GaussNewtonParams& params = {});

  /// Solves from a normalised accel/mag pair, starting at `q_start`. Pure function of the inputs.
  [[nodiscard]] GaussNewtonResult solve(const Eigen::Vector3d& accel, const Eigen::Vector3d& mag,
                                        const Eigen::Quaterniond& q_start, double dip_rad) const;

  /// Processes one sample (validated, rejected and counted when bad). Needs a magnetometer.
  /// False too when the solution is not a finite unit quaternion: the filter is then reset
  /// (counters kept) and counted in state_resets().
  bool update(const ImuSample& s);
  /// Resets after an unhealthy state (poise/core/state_health.h).
  [[nodiscard]] uint64_t state_resets() const { return s_.health.resets; }

  [[nodiscard]] const GaussNewtonResult& result() const { return s_.result; }
  /// Covariance of the world-frame attitude error (rad^2, about ENU x, y, z) of result(): the
  /// least-squares one, sigma^2 (J^T J)^-1 rotated to the world, with sigma^2 the residual's
  /// variance per unit-vector component low-passed over kResidualTauS (the residual has one degree
  /// of freedom: the angle between the two vectors against the dip), plus the external
  /// acceleration the accelerometer norm shows beyond sigma^2 (accel_direction_sensitivity()),
  /// plus pi^2 / 3 on the heading while heading_unknown().
  [[nodiscard]] Eigen::Matrix3d attitude_covariance() const;
  /// True while the field reference is learnt or provisional (field_verify_s > 0): a start next to
  /// a magnet solves every heading from the magnet's field, and nothing tells that yet.
  [[nodiscard]] bool heading_unknown() const {
    return s_.initialized && gp_.verify_s > 0.0 && !s_.gate.verified;
  }
  /// Provisional references replaced by a consistent field (the dip relearnt).
  [[nodiscard]] uint64_t field_relearnt_count() const { return s_.gate.relearnt; }
  [[nodiscard]] bool initialized() const { return s_.initialized; }
  /// kVerified once the field reference is verified (configured, or accepted for field_verify_s):
  /// every estimate is then solved from the sample's own magnetometer (no memory of the field), so
  /// its heading is the field's, disturbed or not; the covariance (from the residual) is what
  /// tells a disturbance. kUnverified while heading_unknown(); kNoReference before an estimate.
  [[nodiscard]] HeadingStatus heading_status() const {
    if (!s_.initialized) {
      return HeadingStatus::kNoReference;
    }
    return heading_unknown() ? HeadingStatus::kUnverified : HeadingStatus::kVerified;
  }
  [[nodiscard]] double dip_rad() const { return s_.dip_rad; }
  [[nodiscard]] const RejectCounters& rejections() const { return s_.rejections; }
  /// Per source (accel, mag) for the last sample: both fused together, or the sample's reason.
  [[nodiscard]] SourceReports sources() const { return {s_.accel, s_.mag}; }
  /// Back to the state of a new filter (parameters kept).
  void reset();
  /// The filter's whole state: two filters with the same parameters and state give the same
  /// outputs for the same samples.
  [[nodiscard]] const GaussNewtonState& state() const { return s_; }
  /// Restores a state taken from state() of a filter with the same parameters.
  void set_state(const GaussNewtonState& state) { s_ = state; }
  [[nodiscard]] const GaussNewtonParams& params() const { return p_; }

 private:
  [[nodiscard]] bool healthy() const;
  void reset_unhealthy();  ///< reset() keeping the counters, one reset counted

  GaussNewtonParams p_;
  FieldGateParams gp_;  ///< the cold-start gate's parameters (from p_)
  GaussNewtonState s_;
};

/// AttitudeFilter adapter.
class GaussNewtonFilter : public AttitudeFilter {
 public:
  explicit GaussNewtonFilter(const GaussNewtonParams& p = {}) : gn_(p) {}
  bool update(const ImuSample& s) override { return gn_.update(s); }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override { return gn_.result().q_world_body; }
  [[nodiscard]] bool initialized() const override { return gn_.initialized(); }
  void reset() override { gn_.reset(); }
  void seed_field(double field_ut, double dip_deg) override {
    GaussNewtonParams p = gn_.params();
    seed_field_reference(field_ut, dip_deg, p.field_magnitude_ut, p.dip_deg);
    gn_ = GaussNewton(p);
  }
  [[nodiscard]] std::map<std::string, uint64_t> rejections() const override {
    auto m = gn_.rejections().to_map();
    if (gn_.state_resets() != 0) {
      m["state_reset"] = gn_.state_resets();
    }
    return m;
  }
  [[nodiscard]] std::optional<Eigen::Matrix3d> attitude_covariance() const override {
    if (!gn_.initialized()) {
      return std::nullopt;
    }
    return gn_.attitude_covariance();
  }
  [[nodiscard]] HeadingStatus heading_status() const override { return gn_.heading_status(); }
  [[nodiscard]] SourceReports sources() const override { return gn_.sources(); }
  [[nodiscard]] const GaussNewton& core() const { return gn_; }

 private:
  GaussNewton gn_;
};

}  // namespace poise
