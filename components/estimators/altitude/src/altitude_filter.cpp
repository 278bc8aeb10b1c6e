#include "poise/altitude/altitude_filter.h"

#include "poise/core/params_check.h"
#include "poise/core/sample_check.h"

#include <cmath>
#include <stdexcept>

namespace poise {

double baro_height_m(double pressure_pa, double reference_pa, bool paper_rounded) {
  if (!std::isfinite(pressure_pa) || !std::isfinite(reference_pa) || pressure_pa <= 0.0 ||
      reference_pa <= 0.0) {
    return std::nan("");
  }
  if (paper_rounded) {
    return 44300.0 * (1.0 - std::pow(pressure_pa / reference_pa, 0.19));  // (7)
  }
  constexpr double kScale = IsaConstants::kT0K / IsaConstants::kLapseKpm;  // 44330.77 m
  constexpr double kExp = IsaConstants::kRAir * IsaConstants::kLapseKpm / IsaConstants::kG;  // 0.19026
  return kScale * (1.0 - std::pow(pressure_pa / reference_pa, kExp));  // (6)
}

double isa_pressure_pa(double height_m, double reference_pa) {
  constexpr double kScale = IsaConstants::kT0K / IsaConstants::kLapseKpm;
  constexpr double kExp = IsaConstants::kRAir * IsaConstants::kLapseKpm / IsaConstants::kG;
  return reference_pa * std::pow(1.0 - height_m / kScale, 1.0 / kExp);
}

const char* to_string(AltitudeMethod m) {
  switch (m) {
    case AltitudeMethod::kTwoStepKf:
      return "two_step_kf";
    case AltitudeMethod::kCfZupt:
      return "cf_zupt";
    case AltitudeMethod::kPiCfZupt:
      return "pi_cf_zupt";
    case AltitudeMethod::kPiCf:
      return "pi_cf";
  }
  return "?";
}

bool parse_altitude_method(const std::string& name, AltitudeMethod& out) {
  for (AltitudeMethod m : {AltitudeMethod::kTwoStepKf, AltitudeMethod::kCfZupt,
                           AltitudeMethod::kPiCfZupt, AltitudeMethod::kPiCf}) {
    if (name == to_string(m)) {
      out = m;
      return true;
    }
  }
  return false;
}

const char* to_string(CfGains g) { return g == CfGains::kPaper ? "paper" : "higgins"; }

bool parse_cf_gains(const std::string& name, CfGains& out) {
  if (name == "paper") {
    out = CfGains::kPaper;
    return true;
  }
  if (name == "higgins") {
    out = CfGains::kHiggins;
    return true;
  }
  return false;
}

void AltitudeParams::validate() const {
  const ParamCheck check("altitude");
  check.positive(gravity_mps2, "gravity_mps2", "m/s^2");
  check.positive(reference_pressure_pa, "barometer.reference_pressure_pa", "Pa");
  check.positive(min_pressure_pa, "barometer.min_pressure_pa", "Pa");
  check.positive(max_pressure_pa, "barometer.max_pressure_pa", "Pa");
  check.require(min_pressure_pa < max_pressure_pa, "barometer.min_pressure_pa", "below barometer.max_pressure_pa (Pa)");
  check.non_negative(max_baro_age_s, "barometer.max_baro_age_s", "s");
  check.positive(sigma_acc_mps2, "cf.sigma_acc_mps2", "m/s^2");
  check.positive(sigma_baro_m, "cf.sigma_baro_m", "m");
  check.non_negative(k_i, "cf.k_i", "1/s^3 when time-scaled");
  check.positive(zupt_gyro_max_rps, "zupt.gyro_max_rps", "rad/s");
  check.positive(zupt_accel_dev_max_mps2, "zupt.accel_dev_max_mps2", "m/s^2");
  check.non_negative(zupt_window_s, "zupt.window_s", "s");
  check.positive(max_dt_s, "max_dt_s", "s");
  check.positive(max_gyro_rps, "limits.max_gyro_rps", "rad/s");
  check.positive(max_accel_mps2, "limits.max_accel_mps2", "m/s^2");
  tilt.validate(check);
}

AltitudeFilter::AltitudeFilter(const AltitudeParams& params) : params_(params) {
  params_.validate();
  params_.tilt.gravity_mps2 = params_.gravity_mps2;
  limits_.max_dt_s = params_.max_dt_s;
  limits_.max_gyro_rps = params_.max_gyro_rps;
  limits_.max_accel_mps2 = params_.max_accel_mps2;
  limits_.min_accel_norm_mps2 = 0.0;  // free fall is a vertical acceleration, not a broken sensor
  s_.tilt = TiltKf(params_.tilt);
  const double r = params_.sigma_acc_mps2 / params_.sigma_baro_m;  // (14)
  k_c_ = Eigen::Vector2d(params_.gains == CfGains::kPaper ? std::sqrt(r) : std::sqrt(2.0 * r), r);
  reset();
}

void AltitudeFilter::reset() {
  s_ = AltitudeFilterState();
  s_.tilt = TiltKf(params_.tilt);
}

bool AltitudeFilter::uses_zupt() const { return params_.method != AltitudeMethod::kPiCf; }

bool AltitudeFilter::uses_integral() const {
  return params_.method == AltitudeMethod::kPiCfZupt || params_.method == AltitudeMethod::kPiCf;
}

void AltitudeFilter::update_stationary(const ImuSample& s, double dt_s) {
  const bool still =
      s.gyro_rps.norm() < params_.zupt_gyro_max_rps &&
      std::abs(s.accel_mps2.norm() - params_.gravity_mps2) < params_.zupt_accel_dev_max_mps2;
  s_.still_time_s = still ? s_.still_time_s + dt_s : 0.0;
  s_.est.stationary = still && s_.still_time_s >= params_.zupt_window_s;
}

void AltitudeFilter::step_cf(double dt_s) {
  // (13)/(19) with the quantities of sample k-1: eps_{k-1}, sum_{i<=k-1} eps_i, a_z,k-1.
  Eigen::Vector2d f(0.0, 0.0);
  if (s_.prev_baro_ok) {
    const double eps = s_.prev_y_b - s_.x(0);  // (15)
    f = k_c_ * eps;                        // (16)
    if (uses_integral()) {
      s_.integral += params_.integral_time_scaled ? eps * dt_s : eps;
      const Eigen::Vector2d ki_vec = params_.integral_velocity_only
                                         ? Eigen::Vector2d(0.0, params_.k_i)
                                         : Eigen::Vector2d(params_.k_i, params_.k_i);
      f += ki_vec * s_.integral;  // (17), (18)
    }
  }
  Eigen::Matrix2d a;
  a << 1.0, dt_s, 0.0, 1.0;
  const Eigen::Vector2d c(dt_s, 1.0);
  s_.x = a * s_.x + a * f * dt_s + c * s_.prev_a_z * dt_s;  // (19); B = A as printed
}

void AltitudeFilter::step_kf(double dt_s, bool baro_available, double y_b) {
  // Method 1: continuous-time noise densities turned into per-step variances so that the steady
  // state of this KF is the Higgins CF (accel PSD s_acc^2, baro PSD s_b^2).
  Eigen::Matrix2d a;
  a << 1.0, dt_s, 0.0, 1.0;
  const Eigen::Vector2d g(0.5 * dt_s * dt_s, dt_s);
  const double q = params_.sigma_acc_mps2 * params_.sigma_acc_mps2 / dt_s;
  s_.x = a * s_.x + g * s_.prev_a_z;
  s_.p_kf = a * s_.p_kf * a.transpose() + g * g.transpose() * q;
  if (baro_available) {
    const double r = params_.sigma_baro_m * params_.sigma_baro_m / dt_s;
    const double s = s_.p_kf(0, 0) + r;
    const Eigen::Vector2d k = s_.p_kf.col(0) / s;
    s_.x += k * (y_b - s_.x(0));
    Eigen::Matrix2d ikh = Eigen::Matrix2d::Identity();
    ikh.col(0) -= k;
    s_.p_kf = ikh * s_.p_kf * ikh.transpose() + k * k.transpose() * r;  // Joseph form
    s_.p_kf = 0.5 * (s_.p_kf + s_.p_kf.transpose());
  }
}

// not split: one filter step in the paper's order (sample checks, tilt KF, vertical acceleration,
// ZUPT, barometer correction, report).
bool AltitudeFilter::update(const ImuSample& s) {
  ImuSample imu = s;
  imu.has_mag = false;  // not used here: neither checked nor counted
  const SampleCheck c = check_imu_sample(imu, s_.have_stamp ? s_.last_stamp_ns : -1, limits_, s_.rejects);
  if (s_.anchor.reanchor(c, s.stamp_ns, limits_.max_dt_s)) {
    s_.last_stamp_ns = s.stamp_ns;  // restart time after a confirmed jump; the state is kept
    s_.still_time_s = 0.0;
  }
  if (!c.accept) {
    reject_sample(to_string(c.reject));
    return false;
  }
  const double dt_s = c.dt_s;
  s_.last_stamp_ns = s.stamp_ns;

  // Barometer: a bad pressure rejects only itself.
  s_.est.baro_fresh = false;
  if (s.has_pressure) {
    const RejectReason why =
        check_pressure(s.pressure_pa, params_.min_pressure_pa, params_.max_pressure_pa, s_.rejects);
    if (why == RejectReason::kCount) {
      s_.last_baro_m = baro_height_m(s.pressure_pa, params_.reference_pressure_pa,
                                   params_.paper_rounded_constants);
      s_.last_baro_stamp_ns = s.stamp_ns;
      s_.have_baro = true;
      s_.est.baro_fresh = true;
      s_.est.baro_height_m = s_.last_baro_m;
    } else {
      s_.baro.mark_rejected(to_string(why));
    }
  } else {
    s_.baro.mark_not_available("no_sample");
  }
  // both stamps in [0, 2^62] ns (checked): the difference fits; negative after time restarted back
  const double baro_age_s = static_cast<double>(s.stamp_ns - s_.last_baro_stamp_ns) * 1e-9;
  const bool baro_ok = s_.have_baro && baro_age_s >= 0.0 && baro_age_s <= params_.max_baro_age_s;

  const bool propagated = s_.have_stamp && s_.tilt.initialized();
  if (!propagated) {
    // First sample or re-anchored time: (re)start the tilt from the accelerometer when needed and
    // propagate nothing.
    s_.have_stamp = true;
    if (!s_.tilt.initialized()) {
      s_.tilt.reset_from_accel(s.accel_mps2);
    }
    s_.still_time_s = 0.0;
  } else {
    s_.tilt.update(s_.prev_gyro, s.accel_mps2, dt_s);  // gyro of sample k-1 (paper 000 (5a))
    if (s_.est.valid) {
      if (params_.method == AltitudeMethod::kTwoStepKf) {
        step_kf(dt_s, baro_ok, s_.last_baro_m);
      } else {
        step_cf(dt_s);
      }
    }
    update_stationary(s, dt_s);
  }
  s_.prev_gyro = s.gyro_rps;

  const Eigen::Vector3d& z = s_.tilt.up_body();
  const Eigen::Vector3d a_s = s.accel_mps2 - params_.gravity_mps2 * z;  // (4)
  const double a_z = z.dot(a_s);                                         // (5)

  if (!s_.est.valid && baro_ok && s_.tilt.initialized()) {
    s_.x = Eigen::Vector2d(s_.last_baro_m, 0.0);
    s_.p_kf = Eigen::Vector2d(params_.sigma_baro_m * params_.sigma_baro_m, 0.25).asDiagonal();
    s_.integral = 0.0;
    s_.est.valid = true;
  }

  s_.est.zupt_applied = false;
  if (s_.est.valid && uses_zupt() && s_.est.stationary) {
    if (params_.method == AltitudeMethod::kTwoStepKf) {
      // v = 0 pseudo-measurement with a tiny variance.
      constexpr double kZuptVar = 1e-6;  // (m/s)^2
      const double sv = s_.p_kf(1, 1) + kZuptVar;
      const Eigen::Vector2d k = s_.p_kf.col(1) / sv;
      s_.x -= k * s_.x(1);
      Eigen::Matrix2d ikh = Eigen::Matrix2d::Identity();
      ikh.col(1) -= k;
      s_.p_kf = ikh * s_.p_kf * ikh.transpose() + k * k.transpose() * kZuptVar;
      s_.p_kf = 0.5 * (s_.p_kf + s_.p_kf.transpose());
    }
    s_.x(1) = 0.0;
    s_.est.zupt_applied = true;
  }

  s_.prev_a_z = a_z;
  s_.prev_baro_ok = baro_ok;
  s_.prev_y_b = s_.last_baro_m;

  s_.est.stamp_ns = s.stamp_ns;
  s_.est.height_m = s_.x(0);
  s_.est.vertical_velocity_mps = s_.x(1);
  s_.est.vertical_accel_mps2 = a_z;
  s_.est.integral_sum_m = s_.integral;
  if (!healthy()) {
    reset_unhealthy();
    return false;
  }
  report_sources(s, propagated);
  return true;
}

bool AltitudeFilter::healthy() {
  const bool full = s_.health.full_due();
  return all_finite(s_.x, s_.integral, s_.prev_a_z, s_.last_baro_m, s_.tilt.up_body(), s_.tilt.ext_accel_body()) &&
         covariance_ok(s_.tilt.covariance(), full) && covariance_ok(s_.p_kf, full);
}

void AltitudeFilter::reset_unhealthy() {
  using S = AltitudeFilterState;
  reset_keeping(s_, [this] { reset(); }, &S::rejects, &S::gyro, &S::accel, &S::baro, &S::zupt);
  reject_sample(kStateResetReason);
}

void AltitudeFilter::reject_sample(const char* why) {
  for (SourceReport* r : {&s_.gyro, &s_.accel, &s_.baro, &s_.zupt}) {
    r->mark_rejected(why);
  }
}

void AltitudeFilter::report_sources(const ImuSample& s, bool propagated) {
  if (propagated) {
    s_.gyro.mark_fused(s.stamp_ns);
  } else {
    s_.gyro.mark_not_available("time_anchor");
  }
  s_.accel.mark_fused(s.stamp_ns);
  if (s_.est.baro_fresh) {
    const double var = params_.sigma_baro_m * params_.sigma_baro_m +
                       (params_.method == AltitudeMethod::kTwoStepKf ? s_.p_kf(0, 0) : 0.0);
    s_.baro.set_innovation(InnovationVector::Constant(1, s_.last_baro_m - s_.x(0)),  // (15)
                         InnovationVector::Constant(1, var));
    s_.baro.mark_fused(s.stamp_ns);
  }
  if (s_.est.zupt_applied) {
    s_.zupt.mark_fused(s.stamp_ns);
  } else {
    s_.zupt.mark_not_available(!uses_zupt() ? "not_used_by_method" : !s_.est.valid ? "not_initialised" : "moving");
  }
}

}  // namespace poise
