// TiltKf: KF1 of the parallel Kalman filter (paper 000 eqs. 4-7; J. K. Lee's tilt + external
// acceleration filter, reference [8] of paper 000 and [10] of paper 003). Reusable on its own
// (the altitude filter builds on it).
//
// Notation (all vectors in the sensor/body frame S)
//   sZ   world up axis seen in S (unit): the tilt. Roll/pitch follow from it.
//   sa   external (non-gravitational) acceleration of the sensor, m/s^2.
//   s_A  accelerometer, specific force, m/s^2: s_A = g sZ + sa + n_A           (1a), (3a)
//   s_G  gyro, rad/s; h = dt, s.
//   x1 = [sZ; sa], z1 = s_A                                                     (4)
//   sZ_k = (I - h[s_G,k-1 x]) sZ_{k-1},  sa_k = c_a sa_{k-1} + eps_a             (5a), (5b)
//   F1, Q1, H1 = [g I | I], M1 = sigma_A^2 I                                     (7a)-(7h)
// (7a): the printed `^S g_{G,k-1}` is the gyro signal s_G at k-1. (7f): H1 = [g I | I].
// The state's covariance is the 6x6 P of x1, order [sZ; sa].
#pragma once

#include "poise/core/params_check.h"
#include "poise/parallel_kf/direction_kf.h"

#include <Eigen/Core>

#include <cstdint>

namespace poise {

/// Parameters of the tilt KF. Defaults: GY-87 data sheet noise (paper 000 Table 1), c_a of the
/// paper, exact propagation + renormalisation on (set both false for the printed equations).
/// See DirectionKfParams for what each extension does.
struct TiltKfParams {
  double sigma_gyro_rps = 0.05 * kRadPerDeg;  ///< sigma_G, rad/s. Raising it trusts the accelerometer more (faster tilt correction, more acceleration leaks in).
  double sigma_accel_mps2 = 0.04;             ///< sigma_A, m/s^2 (400 ug/sqrt(Hz) over ~100 Hz). Raising it slows tilt correction.
  double c_a = 0.1;                           ///< acceleration model coefficient (5b), [0, 1). Paper: 0.1 at 100 Hz.
  double c_a_rate_hz = 0.0;                   ///< > 0: c_a is given at this rate, scaled to dt (c_a^(rate dt)). 0 = per step as printed.
  double gravity_mps2 = 9.81;                 ///< g in H1 (7f), m/s^2.
  bool exact_rotation = true;                 ///< propagate sZ with exp(-h s_G) instead of the first-order (5a) (paper: false; first order lets |sZ| grow without bound at high rates).
  bool renormalize = true;                    ///< renormalise sZ after each step (paper: false).
  double sigma_gyro_extra_rps = 0.0;          ///< extra gyro error std in Q11 (e.g. residual bias), rad/s.
  double initial_var_tilt = 1e-2;             ///< P11 at reset (unit-vector components^2).
  double initial_var_accel = 1.0;             ///< P22 at reset, (m/s^2)^2.

  /// The noise model's checks under the keys tilt.* (every filter built on KF1 runs them: the
  /// parallel KF and the altitude filter); ParamCheck names the filter.
  void validate(const ParamCheck& check) const {
    check.positive(sigma_gyro_rps, "tilt.sigma_gyro_rps", "rad/s");
    check.positive(sigma_accel_mps2, "tilt.sigma_accel_mps2", "m/s^2");
    check.require(c_a >= 0.0 && c_a < 1.0, "tilt.c_a", "in [0, 1)");
    check.non_negative(c_a_rate_hz, "tilt.c_a_rate_hz", "Hz");
    check.non_negative(sigma_gyro_extra_rps, "tilt.sigma_gyro_extra_rps", "rad/s");
  }
  /// Reads the keys of a `tilt:` section with a YamlParamReader (poise/core/yaml_params.h; a
  /// template, so this header needs no yaml-cpp). gravity_mps2 is not among them: a filter that
  /// takes it from the file reads it itself (the altitude filter sets it from its own).
  template <typename Reader>
  void read(Reader& r) {
    r.get("sigma_gyro_rps", sigma_gyro_rps);
    r.get("sigma_accel_mps2", sigma_accel_mps2);
    r.get("c_a", c_a);
    r.get("c_a_rate_hz", c_a_rate_hz);
    r.get("exact_rotation", exact_rotation);
    r.get("renormalize", renormalize);
    r.get("sigma_gyro_extra_rps", sigma_gyro_extra_rps);
  }

  [[nodiscard]] DirectionKfParams direction_params() const {
    DirectionKfParams d;
    d.sigma_gyro_rps = sigma_gyro_rps;
    d.sigma_meas = sigma_accel_mps2;
    d.c = c_a;
    d.c_rate_hz = c_a_rate_hz;
    d.exact_rotation = exact_rotation;
    d.renormalize = renormalize;
    d.sigma_gyro_extra_rps = sigma_gyro_extra_rps;
    return d;
  }
};

/// KF1 of paper 000. Does not validate inputs beyond what it must (the caller - e.g. ParallelKf -
/// rejects and counts bad samples); update() with a non-finite input or non-positive dt is ignored
/// and returns false.
class TiltKf {
 public:
  explicit TiltKf(const TiltKfParams& params = {});

  /// Starts at sZ = normalise(up_body) with sa = 0. A zero/non-finite vector leaves the filter
  /// uninitialised.
  void reset(const Eigen::Vector3d& up_body);
  /// Starts from the accelerometer (sZ = normalise(s_A)).
  void reset_from_accel(const Eigen::Vector3d& accel_mps2) { reset(accel_mps2); }

  /// One step: predict with the gyro (rad/s, sample k-1) over dt_s (5), (7a-e), then correct with
  /// the accelerometer (m/s^2) (6b), (7f-h). Uninitialised: initialises from the accelerometer.
  /// Returns false (state untouched) on non-finite input or dt_s <= 0.
  bool update(const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& accel_mps2, double dt_s);
  /// Time update only (e.g. accelerometer missing or rejected).
  bool predict(const Eigen::Vector3d& gyro_rps, double dt_s);
  /// Measurement update only; `extra_var_mps2sq` inflates M1 (0 = paper).
  bool correct(const Eigen::Vector3d& accel_mps2, double extra_var_mps2sq = 0.0);

  [[nodiscard]] const Eigen::Vector3d& up_body() const { return kf_.u(); }         ///< sZ, unit
  [[nodiscard]] const Eigen::Vector3d& ext_accel_body() const { return kf_.e(); }  ///< sa, m/s^2
  [[nodiscard]] Eigen::Matrix<double, 6, 6> covariance() const { return kf_.covariance(); }
  [[nodiscard]] const DirectionKf& direction_kf() const { return kf_; }
  [[nodiscard]] bool initialized() const { return initialized_; }
  [[nodiscard]] const TiltKfParams& params() const { return params_; }
  /// Last accelerometer innovation s_A - H1 x1^- (m/s^2).
  [[nodiscard]] const Eigen::Vector3d& last_innovation() const { return innovation_; }
  /// Small body-frame rotation (rad) that the last correction applied to the tilt: the part of
  /// the attitude change not explained by the gyro (perpendicular to sZ). Used for bias estimation.
  [[nodiscard]] Eigen::Vector3d last_correction_rotvec() const {
    // sZ+ = sZ- - dtheta x sZ-  =>  dtheta_perp = sZ+ x sZ- (normalised directions; they are
    // unit already with exact propagation and renormalisation)
    if (params_.renormalize && params_.exact_rotation) {
      return kf_.u().cross(z_prior_);
    }
    return kf_.u().normalized().cross(z_prior_.normalized());
  }

  /// Direct access for composite filters (ParallelKf).
  [[nodiscard]] DirectionKf& core() { return kf_; }

 private:
  TiltKfParams params_;
  DirectionKf kf_;
  bool initialized_ = false;
  Eigen::Vector3d innovation_{0.0, 0.0, 0.0};
  Eigen::Vector3d z_prior_{0.0, 0.0, 1.0};  ///< sZ before the last correction
};

}  // namespace poise
