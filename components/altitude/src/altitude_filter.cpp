#include "poise/altitude/altitude_filter.h"

#include "poise/core/sample_check.h"

#include <cmath>
#include <sstream>
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

std::string AltitudeParams::validate() const {
  std::ostringstream err;
  const auto positive = [&err](double v, const char* name) {
    if (!std::isfinite(v) || v <= 0.0) {
      err << name << " must be > 0 (got " << v << "); ";
    }
  };
  const auto non_negative = [&err](double v, const char* name) {
    if (!std::isfinite(v) || v < 0.0) {
      err << name << " must be >= 0 (got " << v << "); ";
    }
  };
  positive(gravity_mps2, "gravity_mps2");
  positive(reference_pressure_pa, "barometer.reference_pressure_pa");
  positive(min_pressure_pa, "barometer.min_pressure_pa");
  positive(max_pressure_pa, "barometer.max_pressure_pa");
  if (min_pressure_pa >= max_pressure_pa) {
    err << "barometer.min_pressure_pa must be below barometer.max_pressure_pa; ";
  }
  non_negative(max_baro_age_s, "barometer.max_baro_age_s");
  positive(sigma_acc_mps2, "cf.sigma_acc_mps2");
  positive(sigma_baro_m, "cf.sigma_baro_m");
  non_negative(k_i, "cf.k_i");
  positive(zupt_gyro_max_rps, "zupt.gyro_max_rps");
  positive(zupt_accel_dev_max_mps2, "zupt.accel_dev_max_mps2");
  non_negative(zupt_window_s, "zupt.window_s");
  positive(max_dt_s, "max_dt_s");
  positive(tilt.sigma_gyro_rps, "tilt.sigma_gyro_rps");
  positive(tilt.sigma_accel_mps2, "tilt.sigma_accel_mps2");
  if (!(tilt.c_a >= 0.0 && tilt.c_a < 1.0)) {
    err << "tilt.c_a must be in [0, 1) (got " << tilt.c_a << "); ";
  }
  std::string s = err.str();
  if (!s.empty()) {
    s.resize(s.size() - 2);
  }
  return s;
}

AltitudeFilter::AltitudeFilter(const AltitudeParams& params) : params_(params) {
  const std::string problems = params_.validate();
  if (!problems.empty()) {
    throw std::invalid_argument("altitude filter parameters: " + problems);
  }
  params_.tilt.gravity_mps2 = params_.gravity_mps2;
  tilt_ = TiltKf(params_.tilt);
  const double r = params_.sigma_acc_mps2 / params_.sigma_baro_m;  // (14)
  k_c_ = Eigen::Vector2d(params_.gains == CfGains::kPaper ? std::sqrt(r) : std::sqrt(2.0 * r), r);
  reset();
}

void AltitudeFilter::reset() {
  tilt_ = TiltKf(params_.tilt);
  est_ = AltitudeEstimate{};
  rejects_ = AltitudeRejects{};
  have_stamp_ = false;
  last_stamp_ns_ = 0;
  have_baro_ = false;
  last_baro_m_ = 0.0;
  last_baro_stamp_ns_ = 0;
  x_.setZero();
  p_kf_.setZero();
  integral_ = 0.0;
  prev_gyro_.setZero();
  prev_a_z_ = 0.0;
  prev_y_b_ = 0.0;
  prev_baro_ok_ = false;
  still_time_s_ = 0.0;
  gyro_ = source_named("gyro");
  accel_ = source_named("accel");
  baro_ = source_named("baro");
  zupt_ = source_named("zupt");
}

bool AltitudeFilter::uses_zupt() const { return params_.method != AltitudeMethod::kPiCf; }

bool AltitudeFilter::uses_integral() const {
  return params_.method == AltitudeMethod::kPiCfZupt || params_.method == AltitudeMethod::kPiCf;
}

void AltitudeFilter::update_stationary(const ImuSample& s, double dt_s) {
  const bool still =
      s.gyro_rps.norm() < params_.zupt_gyro_max_rps &&
      std::abs(s.accel_mps2.norm() - params_.gravity_mps2) < params_.zupt_accel_dev_max_mps2;
  still_time_s_ = still ? still_time_s_ + dt_s : 0.0;
  est_.stationary = still && still_time_s_ >= params_.zupt_window_s;
}

void AltitudeFilter::step_cf(double dt_s) {
  // (13)/(19) with the quantities of sample k-1: eps_{k-1}, sum_{i<=k-1} eps_i, a_z,k-1.
  Eigen::Vector2d f(0.0, 0.0);
  if (prev_baro_ok_) {
    const double eps = prev_y_b_ - x_(0);  // (15)
    f = k_c_ * eps;                        // (16)
    if (uses_integral()) {
      integral_ += params_.integral_time_scaled ? eps * dt_s : eps;
      const Eigen::Vector2d ki_vec = params_.integral_velocity_only
                                         ? Eigen::Vector2d(0.0, params_.k_i)
                                         : Eigen::Vector2d(params_.k_i, params_.k_i);
      f += ki_vec * integral_;  // (17), (18)
    }
  }
  Eigen::Matrix2d a;
  a << 1.0, dt_s, 0.0, 1.0;
  const Eigen::Vector2d c(dt_s, 1.0);
  x_ = a * x_ + a * f * dt_s + c * prev_a_z_ * dt_s;  // (19); B = A as printed
}

void AltitudeFilter::step_kf(double dt_s, bool baro_available, double y_b) {
  // Method 1: continuous-time noise densities turned into per-step variances so that the steady
  // state of this KF is the Higgins CF (accel PSD s_acc^2, baro PSD s_b^2).
  Eigen::Matrix2d a;
  a << 1.0, dt_s, 0.0, 1.0;
  const Eigen::Vector2d g(0.5 * dt_s * dt_s, dt_s);
  const double q = params_.sigma_acc_mps2 * params_.sigma_acc_mps2 / dt_s;
  x_ = a * x_ + g * prev_a_z_;
  p_kf_ = a * p_kf_ * a.transpose() + g * g.transpose() * q;
  if (baro_available) {
    const double r = params_.sigma_baro_m * params_.sigma_baro_m / dt_s;
    const double s = p_kf_(0, 0) + r;
    const Eigen::Vector2d k = p_kf_.col(0) / s;
    x_ += k * (y_b - x_(0));
    Eigen::Matrix2d ikh = Eigen::Matrix2d::Identity();
    ikh.col(0) -= k;
    p_kf_ = ikh * p_kf_ * ikh.transpose() + k * k.transpose() * r;  // Joseph form
    p_kf_ = 0.5 * (p_kf_ + p_kf_.transpose());
  }
}

bool AltitudeFilter::update(const ImuSample& s) {
  if (!s.has_accel || !s.has_gyro || !s.accel_mps2.allFinite() || !s.gyro_rps.allFinite()) {
    ++rejects_.non_finite_imu;
    reject_sample("non_finite_imu");
    return false;
  }
  TimeStep step;
  if (!advance_stamp(s.stamp_ns, have_stamp_, last_stamp_ns_, params_.max_dt_s, rejects_.non_monotonic_stamp,
                     rejects_.dt_gap, step)) {
    reject_sample("non_monotonic_stamp");
    return false;
  }
  const double dt_s = step.dt_s;
  const bool gap = step.kind == TimeStep::kGap;

  // Barometer: a bad pressure rejects only itself.
  est_.baro_fresh = false;
  if (s.has_pressure) {
    const bool ok = std::isfinite(s.pressure_pa) && s.pressure_pa > 0.0 &&
                    s.pressure_pa >= params_.min_pressure_pa &&
                    s.pressure_pa <= params_.max_pressure_pa;
    if (ok) {
      last_baro_m_ = baro_height_m(s.pressure_pa, params_.reference_pressure_pa,
                                   params_.paper_rounded_constants);
      last_baro_stamp_ns_ = s.stamp_ns;
      have_baro_ = true;
      est_.baro_fresh = true;
      est_.baro_height_m = last_baro_m_;
    } else {
      ++rejects_.bad_pressure;
      baro_.mark_rejected("bad_pressure");
    }
  } else {
    baro_.mark_not_available("no_sample");
  }
  const bool baro_ok =
      have_baro_ && static_cast<double>(s.stamp_ns - last_baro_stamp_ns_) * 1e-9 <=
                        params_.max_baro_age_s;

  const bool propagated = have_stamp_ && !gap && tilt_.initialized();
  if (!propagated) {
    // First sample or re-anchored time: (re)start the tilt from the accelerometer when needed and
    // propagate nothing.
    have_stamp_ = true;
    if (!tilt_.initialized()) {
      tilt_.reset_from_accel(s.accel_mps2);
    }
    still_time_s_ = 0.0;
  } else {
    tilt_.update(prev_gyro_, s.accel_mps2, dt_s);  // gyro of sample k-1 (paper 000 (5a))
    if (est_.valid) {
      if (params_.method == AltitudeMethod::kTwoStepKf) {
        step_kf(dt_s, baro_ok, last_baro_m_);
      } else {
        step_cf(dt_s);
      }
    }
    update_stationary(s, dt_s);
  }
  prev_gyro_ = s.gyro_rps;

  const Eigen::Vector3d& z = tilt_.up_body();
  const Eigen::Vector3d a_s = s.accel_mps2 - params_.gravity_mps2 * z;  // (4)
  const double a_z = z.dot(a_s);                                         // (5)

  if (!est_.valid && baro_ok && tilt_.initialized()) {
    x_ = Eigen::Vector2d(last_baro_m_, 0.0);
    p_kf_ = Eigen::Vector2d(params_.sigma_baro_m * params_.sigma_baro_m, 0.25).asDiagonal();
    integral_ = 0.0;
    est_.valid = true;
  }

  est_.zupt_applied = false;
  if (est_.valid && uses_zupt() && est_.stationary) {
    if (params_.method == AltitudeMethod::kTwoStepKf) {
      // v = 0 pseudo-measurement with a tiny variance.
      constexpr double kZuptVar = 1e-6;  // (m/s)^2
      const double sv = p_kf_(1, 1) + kZuptVar;
      const Eigen::Vector2d k = p_kf_.col(1) / sv;
      x_ -= k * x_(1);
      Eigen::Matrix2d ikh = Eigen::Matrix2d::Identity();
      ikh.col(1) -= k;
      p_kf_ = ikh * p_kf_ * ikh.transpose() + k * k.transpose() * kZuptVar;
      p_kf_ = 0.5 * (p_kf_ + p_kf_.transpose());
    }
    x_(1) = 0.0;
    est_.zupt_applied = true;
  }

  prev_a_z_ = a_z;
  prev_baro_ok_ = baro_ok;
  prev_y_b_ = last_baro_m_;

  est_.stamp_ns = s.stamp_ns;
  est_.height_m = x_(0);
  est_.vertical_velocity_mps = x_(1);
  est_.vertical_accel_mps2 = a_z;
  est_.integral_sum_m = integral_;
  report_sources(s, propagated);
  return true;
}

void AltitudeFilter::reject_sample(const char* why) {
  for (SourceReport* r : {&gyro_, &accel_, &baro_, &zupt_}) {
    r->mark_rejected(why);
  }
}

void AltitudeFilter::report_sources(const ImuSample& s, bool propagated) {
  if (propagated) {
    gyro_.mark_fused(s.stamp_ns);
  } else {
    gyro_.mark_not_available("time_anchor");
  }
  accel_.mark_fused(s.stamp_ns);
  if (est_.baro_fresh) {
    const double var = params_.sigma_baro_m * params_.sigma_baro_m +
                       (params_.method == AltitudeMethod::kTwoStepKf ? p_kf_(0, 0) : 0.0);
    baro_.set_innovation(InnovationVector::Constant(1, last_baro_m_ - x_(0)),  // (15)
                         InnovationVector::Constant(1, var));
    baro_.mark_fused(s.stamp_ns);
  }
  if (est_.zupt_applied) {
    zupt_.mark_fused(s.stamp_ns);
  } else {
    zupt_.mark_not_available(!uses_zupt() ? "not_used_by_method" : !est_.valid ? "not_initialised" : "moving");
  }
}

}  // namespace poise
