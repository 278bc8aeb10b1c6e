// AltitudeFilter: vertical velocity and height from IMU + barometer (paper 003, S.-I. Ji and
// J. K. Lee, J. ICROS 2016; readings in ESTIMATORS.md section 5).
//
// Notation (body frame S = the IMU's axes; world frame ENU, z up)
//   y_a, y_g   accelerometer (specific force, m/s^2) and gyro (rad/s) in S            (2), (3)
//   sZ         world up axis seen in S, from the tilt KF (TiltKf, paper 000 KF1, ref. [10])
//   a_s        external acceleration in S:  a_s = y_a - g sZ                          (4)
//   a_z        vertical acceleration (world up): a_z = sZ^T a_s, m/s^2                (5)
//   P, P0      static pressure, reference pressure (QNH), Pa
//   h_b        barometric height: h_b = (T0/L) (1 - (P/P0)^(R L / g)), ISA constants   (6), (7)
//              (44330.8 m and exponent 0.19026; the paper rounds to 44300 and 0.19)
//   x = [h; v] height (m) and vertical velocity (m/s)                                 (12)
//   A = [[1, dt], [0, 1]],  B = A (as printed),  C = [dt; 1] (applied to a_z dt)        (13)
//   eps_k = y_B,k - h_k  (baro innovation, m)                                           (15)
//   F_{k-1} = K_c eps_{k-1} + K_i sum_{i<=k-1} eps_i   (PI correction, K_d = 0)           (17)-(18)
//   x_k = A x_{k-1} + B F_{k-1} dt + C a_z,k-1 dt                                       (13), (19)
//   K_c = [sqrt(s_acc/s_b); s_acc/s_b]   printed (14): damping ratio 0.5
//       = [sqrt(2 s_acc/s_b); s_acc/s_b] Higgins 1975 steady-state KF (ref. [12]): damping 0.707
// Our readings (ESTIMATORS.md asks to choose and document):
//   - K_i is a scalar added to the 2-vector K_c eps: we apply it as K_i [1; 1] (the literal
//     broadcast of (17)); `integral_velocity_only` applies it as K_i [0; 1] instead (the paper says
//     it tuned K_i for the velocity). The sum is a plain sum over samples as printed (so K_i is
//     per-sample and rate-dependent, and with K_i = 0.05 at 100 Hz the loop is unstable for the
//     gains of (14)); by default (`integral_time_scaled`) each term is multiplied by dt instead
//     (K_i = 0.05 1/s^3, rate-independent, stable). Default gains: Higgins (measured: the printed
//     gains lose to method 2 on the fast random test).
//   - ZUPT (ref. [8], [13]): the sample is stationary when, for at least `zupt_window_s`, every
//     sample had |y_g| < zupt_gyro_max_rps and ||y_a| - g| < zupt_accel_dev_max_mps2; then v = 0.
//   - Method 1 (two-step KF + ZUPT, ref. [8]): a 2-state linear KF on the same model, a_z as the
//     input with process std s_acc, the baro with std s_b; ZUPT as a v = 0 pseudo-measurement.
// Inputs are validated by the shared check (poise/core/sample_check.h): a missing, non-finite or
// beyond-full-scale gyro or accelerometer, a stamp < 0 or > 2^62 ns, a stamp not after the last
// one and an over-long gap reject the sample (counted per reason, state untouched; time restarts
// after two samples that agree, StampAnchor); a non-finite pressure or one outside
// [min_pressure_pa, max_pressure_pa] rejects only the pressure. Free fall (|y_a| ~ 0) is accepted:
// it is a vertical acceleration this filter must integrate.
#pragma once

#include "poise/core/sample_check.h"
#include "poise/core/source_report.h"
#include "poise/core/state_health.h"
#include "poise/core/types.h"
#include "poise/parallel_kf/tilt_kf.h"

#include <Eigen/Core>

#include <cstdint>
#include <optional>
#include <string>

namespace poise {

/// ISA constants (ESTIMATORS.md section 5).
struct IsaConstants {
  static constexpr double kT0K = 288.15;           ///< sea-level temperature, K
  static constexpr double kLapseKpm = 0.0065;      ///< temperature lapse rate, K/m
  static constexpr double kRAir = 287.05;          ///< specific gas constant of air, J/(kg K)
  static constexpr double kG = 9.80665;            ///< standard gravity, m/s^2
  static constexpr double kP0Pa = 101325.0;        ///< standard sea-level pressure, Pa
};

/// Barometric height (m) above the level where the pressure is `reference_pa`, ISA (6).
/// `paper_rounded` uses the paper's 44300 m and exponent 0.19 (7). NaN for non-positive input.
double baro_height_m(double pressure_pa, double reference_pa, bool paper_rounded = false);
/// Inverse of baro_height_m (exact ISA): pressure (Pa) at height h above the reference level.
double isa_pressure_pa(double height_m, double reference_pa);

/// The vertical-velocity methods of paper 003 Table 3 (+ Fig. 8's "method 3 without ZUPT").
enum class AltitudeMethod {
  kTwoStepKf,  ///< method 1: tilt KF + 2-state KF + ZUPT (ref. [8])
  kCfZupt,     ///< method 2: tilt KF + conventional CF (13) + ZUPT
  kPiCfZupt,   ///< method 3 (paper, default): tilt KF + PI CF (19) + ZUPT
  kPiCf,       ///< method 3 without ZUPT (Fig. 8)
};
/// "two_step_kf", "cf_zupt", "pi_cf_zupt", "pi_cf".
const char* to_string(AltitudeMethod m);
/// Parses a method name; false when unknown.
bool parse_altitude_method(const std::string& name, AltitudeMethod& out);

/// Which K_c of the same model: printed (14) or the Higgins steady-state KF gains.
enum class CfGains { kPaper, kHiggins };
const char* to_string(CfGains g);
bool parse_cf_gains(const std::string& name, CfGains& out);

/// The tilt-KF parameters the altitude filter uses by default (see AltitudeParams::tilt).
inline TiltKfParams default_altitude_tilt_params() {
  TiltKfParams t;
  t.exact_rotation = true;
  t.renormalize = true;
  t.sigma_gyro_extra_rps = 0.2 * kRadPerDeg;
  return t;
}

/// Parameters. Defaults: paper 003 configuration (method 3, K_i = 0.05), tuned noise levels for a
/// GY-87 (MPU6050 + BMP180) at 100 Hz. See config/filters/altitude.yaml.
struct AltitudeParams {
  AltitudeMethod method = AltitudeMethod::kPiCfZupt;
  /// Stage 1 (its gravity_mps2 is overridden by gravity_mps2). Deviations from the paper-000
  /// defaults, measured in docs/ESTIMATORS_ALTITUDE_VEHICLE.md: sZ propagated exactly and
  /// renormalised (the first-order (5a) grows |sZ| by ~h^2|w|^2/2 per step: +25 % after 50 s of hand
  /// motion, which biases a_z (5) by metres per second squared), and a gyro-bias allowance in Q.
  TiltKfParams tilt = default_altitude_tilt_params();
  double gravity_mps2 = 9.80665;          ///< g in (4) and in the tilt KF, m/s^2

  // Barometer (6), (7)
  double reference_pressure_pa = IsaConstants::kP0Pa;  ///< P0 / QNH, Pa. Height is above the level of this pressure.
  bool paper_rounded_constants = false;   ///< use 44300 m / 0.19 (7) instead of exact ISA (6)
  double min_pressure_pa = 30000.0;       ///< below: rejected (BMP180 range 300-1100 hPa)
  double max_pressure_pa = 110000.0;      ///< above: rejected
  double max_baro_age_s = 0.5;            ///< the last baro height is held this long between baro samples

  // Complementary filter (13), (14)
  CfGains gains = CfGains::kHiggins;      ///< printed (14) or Higgins steady-state gains
  double sigma_acc_mps2 = 0.04;           ///< s_acc in (14): vertical-acceleration noise std, m/s^2 (MPU6050 sheet). Raising it trusts the baro more.
  double sigma_baro_m = 0.3;              ///< s_b in (14): baro height noise std, m (BMP180 0.03 hPa ~ 0.25 m). Raising it trusts the IMU more.

  // PI correction (17)-(19)
  double k_i = 0.05;                      ///< K_i (18); applies to methods pi_cf_zupt and pi_cf. 1/s^3 when time-scaled.
  bool integral_velocity_only = false;    ///< K_i [0; 1] instead of K_i [1; 1]
  /// Sum eps_i dt (default) instead of the printed plain sum eps_i. The plain sum makes K_i
  /// per-sample: at 100 Hz K_i = 0.05 is 5 s^-3, and the third-order loop s^3 + k1 s^2 + k2 s + K
  /// is unstable unless k1 k2 > K (k1 k2 = 0.08 with the default noise levels). Measured in the doc.
  bool integral_time_scaled = true;

  // ZUPT
  double zupt_gyro_max_rps = 0.05;        ///< stationary if |y_g| below this, rad/s
  double zupt_accel_dev_max_mps2 = 0.15;  ///< and ||y_a| - g| below this, m/s^2
  double zupt_window_s = 0.25;            ///< for at least this long, s

  // Time and full scale (YAML limits.*)
  double max_dt_s = 0.2;                  ///< a larger stamp gap is refused and re-anchors time (counted)
  double max_gyro_rps = SampleLimits{}.max_gyro_rps;      ///< |y_g| above: sample rejected, rad/s
  double max_accel_mps2 = SampleLimits{}.max_accel_mps2;  ///< |y_a| above: sample rejected, m/s^2

  /// Throws std::invalid_argument naming the first key out of range, its range and unit (ParamCheck).
  void validate() const;
};

/// Loads AltitudeParams from a YAML file (keys as in config/filters/altitude.yaml); unknown keys
/// and out-of-range values throw std::runtime_error with the file name and what to do.
AltitudeParams load_altitude_params(const std::string& path);

/// One output sample.
struct AltitudeEstimate {
  int64_t stamp_ns = 0;
  double height_m = 0.0;                ///< h, above the reference pressure level, m
  double vertical_velocity_mps = 0.0;   ///< v, world up, m/s
  double vertical_accel_mps2 = 0.0;     ///< a_z (5), m/s^2
  double baro_height_m = 0.0;           ///< raw h_b (6) of the last valid pressure, m
  bool baro_fresh = false;              ///< a valid pressure came with this sample
  bool stationary = false;              ///< ZUPT detector state (computed for every method)
  bool zupt_applied = false;            ///< v was forced to 0 at this sample
  double integral_sum_m = 0.0;          ///< sum eps_i of (17) (m, or m s when time-scaled)
  bool valid = false;                   ///< filter initialised (tilt + first baro)
};

/// Rejection counters by reason of the shared check (never reset except by reset()): the IMU
/// reasons of check_imu_sample() and non_finite_pressure / pressure_out_of_range.
using AltitudeRejects = RejectCounters;

/// Everything the altitude filter carries from one sample to the next besides its parameters:
/// inspect it, save it, restore it into a filter with the same parameters (`set_state`).
struct AltitudeFilterState {
  TiltKf tilt;
  AltitudeEstimate est;
  AltitudeRejects rejects;
  bool have_stamp = false;
  int64_t last_stamp_ns = 0;
  StampAnchor anchor;  ///< restarts time after a stamp jump (two agreeing samples)
  bool have_baro = false;
  double last_baro_m = 0.0;
  int64_t last_baro_stamp_ns = 0;
  Eigen::Vector2d x{0.0, 0.0};  ///< [h; v], m and m/s
  Eigen::Matrix2d p_kf = Eigen::Matrix2d::Zero();
  double integral = 0.0;        ///< sum eps_i
  // Quantities of sample k-1 used by (19)
  Eigen::Vector3d prev_gyro{0.0, 0.0, 0.0};
  double prev_a_z = 0.0;
  double prev_y_b = 0.0;
  bool prev_baro_ok = false;
  double still_time_s = 0.0;    ///< how long every sample has been "still", s
  // Per-source reports of the last sample.
  SourceReport gyro{Source::kGyro};
  SourceReport accel{Source::kAccel};
  SourceReport baro{Source::kBaro};
  SourceReport zupt{Source::kZupt};
  StateHealth health;  ///< resets after an unhealthy update (poise/core/state_health.h)
};

class AltitudeFilter {
 public:
  /// Throws std::invalid_argument when params.validate() does.
  explicit AltitudeFilter(const AltitudeParams& params = {});

  /// Back to the state of a new filter (parameters kept).
  void reset();
  /// The filter's whole state: two filters with the same parameters and state give the same
  /// outputs for the same samples.
  [[nodiscard]] const AltitudeFilterState& state() const { return s_; }
  /// Restores a state taken from state() of a filter with the same parameters.
  void set_state(const AltitudeFilterState& state) { s_ = state; }
  /// Processes one sample (IMU and, when has_pressure, the barometer; a magnetometer is ignored).
  /// Returns false when the sample was rejected as a whole (see AltitudeRejects); a bad pressure
  /// alone returns true.
  /// False too when the update left the state non-finite or a covariance not one: the filter is
  /// then reset (counters kept), counted in state_resets() and starts again from the next sample.
  bool update(const ImuSample& sample);
  /// Resets after an unhealthy state (poise/core/state_health.h).
  [[nodiscard]] uint64_t state_resets() const { return s_.health.resets; }

  [[nodiscard]] const AltitudeEstimate& estimate() const { return s_.est; }
  [[nodiscard]] const AltitudeRejects& rejects() const { return s_.rejects; }
  [[nodiscard]] const AltitudeParams& params() const { return params_; }
  [[nodiscard]] const TiltKf& tilt() const { return s_.tilt; }
  /// K_c in use: [height gain 1/s, velocity gain 1/s^2].
  [[nodiscard]] const Eigen::Vector2d& cf_gain() const { return k_c_; }
  /// Covariance of [h; v] (method 1 only; zero otherwise).
  [[nodiscard]] const Eigen::Matrix2d& kf_covariance() const { return s_.p_kf; }
  /// Per source for the last sample, in this order: gyro (tilt propagation), accel (tilt
  /// correction and a_z), baro (innovation eps (15) = h_b - h, m, variance s_b^2 (+ P_hh for the
  /// two-step KF); rejected "non_finite_pressure" / "pressure_out_of_range"), zupt (fused when v was forced to 0; not available
  /// "moving" or "not_used_by_method").
  [[nodiscard]] SourceReports sources() const { return {s_.gyro, s_.accel, s_.baro, s_.zupt}; }

 private:
  void step_cf(double dt_s);
  void step_kf(double dt_s, bool baro_available, double y_b);
  void update_stationary(const ImuSample& s, double dt_s);
  [[nodiscard]] bool uses_zupt() const;
  [[nodiscard]] bool uses_integral() const;

  AltitudeParams params_;
  SampleLimits limits_;            ///< the shared check's limits, from the parameters
  Eigen::Vector2d k_c_{0.0, 0.0};  ///< from the parameters
  AltitudeFilterState s_;
  void reject_sample(const char* why);
  void report_sources(const ImuSample& s, bool propagated);
  [[nodiscard]] bool healthy();
  void reset_unhealthy();  ///< reset() keeping the counters, one reset counted
};

/// Heights relative to the start: the zero is the mean barometric height of the valid estimates
/// over the first `window_ns` (one BMP180 sample is ~0.3 m noisy; 1 s averages ~30-100 of them).
/// Pure: fed the filter's estimates with their stamps.
class StartZero {
 public:
  explicit StartZero(int64_t window_ns = 1'000'000'000) : window_ns_(window_ns) {}
  /// Adds one estimate; returns the zero once the window has passed with at least one fresh
  /// barometric height (then fixed for good), nullopt before.
  std::optional<double> add(const AltitudeEstimate& e) {
    if (zero_ || !e.valid) {
      return zero_;
    }
    if (e.baro_fresh) {
      sum_m_ += e.baro_height_m;
      ++n_;
    }
    if (!started_) {
      started_ = true;
      start_ns_ = e.stamp_ns;
    }
    if (e.stamp_ns - start_ns_ >= window_ns_ && n_ > 0) {
      zero_ = sum_m_ / static_cast<double>(n_);
    }
    return zero_;
  }
  [[nodiscard]] std::optional<double> zero() const { return zero_; }

 private:
  int64_t window_ns_;
  bool started_ = false;
  int64_t start_ns_ = 0;
  double sum_m_ = 0.0;
  int n_ = 0;
  std::optional<double> zero_;
};

}  // namespace poise
