#include "poise/gauss_newton/gauss_newton.h"
#include "poise/core/yaml_params.h"

#include "poise/core/params_check.h"

#include <algorithm>
#include <stdexcept>

namespace poise {

void GaussNewtonParams::validate(const char* filter) const {
  const ParamCheck check(filter);
  check.require(max_iterations >= 1 && max_iterations <= 100, "max_iterations", "in [1, 100] (per sample)");
  check.non_negative(tolerance_rad, "tolerance_rad", "rad");
  check.positive(mag_weight, "mag_weight", "relative to the accelerometer rows");
  check.require(std::isnan(dip_deg) || std::abs(dip_deg) <= 90.0, "dip_deg", "in [-90, 90] (deg) or null");
  check.require(startup_samples >= 1, "startup_samples", ">= 1 (samples)");
  check.require(std::isnan(field_magnitude_ut) || (std::isfinite(field_magnitude_ut) && field_magnitude_ut > 0.0),
                "field_magnitude_ut", "> 0 (uT) or null");
  check.non_negative(field_verify_s, "field_verify_s", "s, 0 = verified when learnt");
  check.require(use_magnetometer != MagnetometerUse::kOff, "use_magnetometer",
                "auto or true (Gauss-Newton needs the magnetometer in every sample; for 6-axis input "
                "use parallel_kf or selective_ekf)");
  poise::validate(limits, check);
}

GaussNewton::GaussNewton(const GaussNewtonParams& params) : p_(params) {
  p_.validate();
  // the cold-start gate: the default tolerances and start-up, a fixed reference (it only judges
  // whether the start-up field holds), never re-acquired or forced
  gp_.field_magnitude_ut = p_.field_magnitude_ut;
  gp_.dip_deg = p_.dip_deg;
  gp_.reference_tau_s = 0.0;
  gp_.reacquire_s = 0.0;
  gp_.max_reject_s = 0.0;
  gp_.verify_s = p_.field_verify_s;
  reset();
}

void GaussNewton::reset() {
  s_ = GaussNewtonState{};
  s_.dip_rad = std::isfinite(p_.dip_deg) ? p_.dip_deg * kRadPerDeg : 0.0;
  s_.gate.reset(gp_);
}

GaussNewtonResult GaussNewton::solve(const Eigen::Vector3d& accel, const Eigen::Vector3d& mag,
                                     const Eigen::Quaterniond& q_start, double dip_rad) const {
  const Eigen::Vector3d a = accel.normalized();
  const Eigen::Vector3d m = mag.normalized();
  const Eigen::Vector3d u = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d r(0.0, std::cos(dip_rad), -std::sin(dip_rad));
  const double w = p_.mag_weight;
  GaussNewtonResult out;
  Eigen::Quaterniond q = q_start.normalized();
  Eigen::Matrix<double, 6, 1> e;
  Eigen::Matrix<double, 6, 3> j;
  for (int it = 0; it < p_.max_iterations; ++it) {
    const Eigen::Matrix3d rt = q.toRotationMatrix().transpose();
    const Eigen::Vector3d pu = rt * u;
    const Eigen::Vector3d pr = rt * r;
    e.head<3>() = a - pu;
    e.tail<3>() = w * (m - pr);
    // R(q exp d)^T v = exp(-d) R^T v ~ R^T v + [R^T v x] d  =>  J = -[[pu x]; w [pr x]]
    j.topRows<3>() = -skew(pu);
    j.bottomRows<3>() = -w * skew(pr);
    const Eigen::Matrix3d jtj = j.transpose() * j;
    const Eigen::Vector3d delta = -jtj.ldlt().solve(j.transpose() * e);  // (2)
    if (!delta.allFinite()) {
      break;
    }
    q = (q * quat_exp(delta)).normalized();
    out.iterations = it + 1;
    if (delta.norm() < p_.tolerance_rad) {
      break;
    }
  }
  const Eigen::Matrix3d rt = q.toRotationMatrix().transpose();
  e.head<3>() = a - rt * u;
  e.tail<3>() = w * (m - rt * r);
  out.residual = e.norm();
  out.q_world_body = quat_canonical(q);
  j.topRows<3>() = -skew(rt * u);
  j.bottomRows<3>() = -w * skew(rt * r);
  out.information_body = j.transpose() * j;
  out.up_body = rt * u;
  return out;
}

Eigen::Matrix3d accel_direction_sensitivity(const Eigen::Matrix3d& information_body, const Eigen::Vector3d& up_body) {
  // d delta = -(J^T J)^-1 J_a^T d a for a change d a of the accelerometer rows; with
  // E[d a d a^T] = I per unit variance, the covariance is (J^T J)^-1 J_a^T J_a (J^T J)^-1 and
  // J_a^T J_a = [p x]^T [p x] = I - p p^T for the unit p = up_body (the along-p part is normalised away)
  const Eigen::Vector3d p = up_body.normalized();
  const Eigen::Matrix3d inv = information_body.inverse();
  const Eigen::Matrix3d s = inv * (Eigen::Matrix3d::Identity() - p * p.transpose()) * inv;
  return 0.5 * (s + s.transpose());
}

bool GaussNewton::update(const ImuSample& s) {
  const SampleCheck c = check_imu_sample(s, s_.last_stamp_ns, p_.limits, s_.rejections, p_.use_magnetometer);
  if (s_.anchor.reanchor(c, s.stamp_ns, p_.limits.max_dt_s)) {
    s_.last_stamp_ns = s.stamp_ns;
  }
  if (!c.accept) {
    s_.accel.mark_rejected(to_string(c.reject));
    s_.mag.mark_rejected(to_string(c.reject));
    return false;
  }
  if (!c.mag_ok) {  // the solution needs both vectors
    s_.accel.mark_rejected("no_mag");
    if (c.mag_reject != RejectReason::kCount) {
      s_.mag.mark_rejected(to_string(c.mag_reject));
    } else {
      s_.mag.mark_not_available(c.mag_absent);
    }
    return false;
  }
  s_.last_stamp_ns = s.stamp_ns;
  if (!std::isfinite(p_.dip_deg) && s_.dip_n < p_.startup_samples) {
    // measured dip = angle(a, m) - 90 deg
    s_.dip_sum_rad += angle_between_vectors(s.accel_mps2, s.mag_ut) - 0.5 * kPi;
    ++s_.dip_n;
    s_.dip_rad = s_.dip_sum_rad / s_.dip_n;
  }
  const double dt = s_.initialized && c.dt_s > 0.0 ? c.dt_s : 0.0;
  if (gp_.verify_s > 0.0 && !s_.gate.verified &&
      s_.gate.step(gp_, s.mag_ut, s.accel_mps2, dt) == FieldVerdict::kRelearnt && !std::isfinite(p_.dip_deg)) {
    s_.dip_rad = s_.gate.dip_rad;  // a provisional reference gave way to a consistent field: its dip
  }
  Eigen::Quaterniond start = s_.result.q_world_body;
  if (!s_.initialized) {
    // Closed-form start (TRIAD): body axes of world up and horizontal north.
    Eigen::Matrix3d r_body_world;
    if (body_world_axes_from_up_forward(s.accel_mps2, s.mag_ut, r_body_world)) {
      // columns: north (x_NWU), west (y_NWU), up in body  ->  R_world_body for NWU, then ENU.
      start = quat_enu_nwu() * Eigen::Quaterniond(Eigen::Matrix3d(r_body_world.transpose()));
    }
  }
  s_.result = solve(s.accel_mps2, s.mag_ut, start, s_.dip_rad);
  // Residual variance per unit-vector component: two unit vectors give four constraints on three
  // angles, so the residual has one degree of freedom (the angle between them against the dip):
  // E|e|^2 = sigma^2. Averaged over kResidualTauS (one sample of one degree of freedom is often
  // near zero by chance).
  const double r2 = s_.result.residual * s_.result.residual;
  const double a_lp = dt / (kResidualTauS + dt);
  s_.residual2_lp = s_.initialized ? s_.residual2_lp + a_lp * (r2 - s_.residual2_lp) : r2;
  // The accelerometer norm against the gravity it reads (its mean over kGravityNormTauS, cumulative
  // at first): what departs from it is the vertical external acceleration (and noise), for the
  // covariance's external-acceleration term. Averaged over kResidualTauS like the residual.
  const double norm = s.accel_mps2.norm();
  ++s_.gravity_n;
  const double a_g = std::max(1.0 / static_cast<double>(s_.gravity_n), dt / (kGravityNormTauS + dt));
  s_.gravity_mps2 += a_g * (norm - s_.gravity_mps2);
  const double dev2 = (norm - s_.gravity_mps2) * (norm - s_.gravity_mps2);
  s_.norm_dev2_lp = s_.initialized ? s_.norm_dev2_lp + a_lp * (dev2 - s_.norm_dev2_lp) : dev2;
  s_.initialized = true;
  if (!healthy()) {
    reset_unhealthy();
    return false;
  }
  s_.accel.mark_fused(s.stamp_ns);
  s_.mag.mark_fused(s.stamp_ns);
  return true;
}

Eigen::Matrix3d GaussNewton::attitude_covariance() const {
  // least squares: P_body = sigma^2 (J^T J)^-1 at the solution; world = R P_body R^T (the error
  // q_true q_est^-1 = exp(R delta) for q_true = q_est exp(delta)). sigma^2 never below the
  // kMinResidualVar floor, so P is positive definite.
  const double var = std::max(s_.residual2_lp, kMinResidualVar);
  Eigen::Matrix3d p_body = var * s_.result.information_body.inverse();
  // external acceleration: the accelerometer direction's variance the norm shows beyond sigma^2
  // (accel_direction_sensitivity(); isotropic: each axis as large as the vertical one)
  const double g = s_.gravity_mps2;
  const double excess = g > 0.0 ? s_.norm_dev2_lp / (g * g) - var : 0.0;
  if (excess > 0.0) {
    p_body += excess * accel_direction_sensitivity(s_.result.information_body, s_.result.up_body);
  }
  const Eigen::Matrix3d r = s_.result.q_world_body.toRotationMatrix();
  Eigen::Matrix3d p = r * p_body * r.transpose();
  p = 0.5 * (p + p.transpose());
  if (heading_unknown()) {
    p(2, 2) += kUnknownHeadingVarRad2;
  }
  return p;
}

bool GaussNewton::healthy() const {
  // no covariance: the state is the solution and the learnt dip
  const Eigen::Quaterniond& q = s_.result.q_world_body;
  return all_finite(q.coeffs(), s_.dip_rad, s_.dip_sum_rad) && std::abs(q.norm() - 1.0) < 1e-6;
}

void GaussNewton::reset_unhealthy() {
  using S = GaussNewtonState;
  reset_keeping(s_, [this] { reset(); }, &S::rejections, &S::accel, &S::mag);
  s_.accel.mark_rejected(kStateResetReason);
  s_.mag.mark_rejected(kStateResetReason);
}

GaussNewtonParams load_gauss_newton_params(const std::string& path) {
  return load_params_file(path, "Gauss-Newton parameter file", "gauss_newton", GaussNewtonParams{},
                          [](YamlParamReader& r, GaussNewtonParams& p) {
                            p.read(r);
                            read_magnetometer_use(r, p.use_magnetometer);
                          });
}

}  // namespace poise
