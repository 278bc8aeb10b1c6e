#include "poise/vehicle/vehicle_estimator.h"

#include "poise/core/params_check.h"
#include "poise/core/attitude.h"
#include "poise/core/sample_check.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace poise {

const char* to_string(VehicleMode m) {
  switch (m) {
    case VehicleMode::kSwitched:
      return "switched";
    case VehicleMode::kTriad:
      return "triad";
    case VehicleMode::kEkf:
      return "ekf";
  }
  return "?";
}

bool parse_vehicle_mode(const std::string& name, VehicleMode& out) {
  for (VehicleMode m : {VehicleMode::kSwitched, VehicleMode::kTriad, VehicleMode::kEkf}) {
    if (name == to_string(m)) {
      out = m;
      return true;
    }
  }
  return false;
}

void VehicleParams::validate() const {
  const ParamCheck check("vehicle");
  check.positive(model.i_x_kgm2, "model.i_x_kgm2", "kg m^2");
  check.positive(model.i_y_kgm2, "model.i_y_kgm2", "kg m^2");
  check.non_negative(model.k_x_nm_per_rad, "model.k_x_nm_per_rad", "N m/rad");
  check.non_negative(model.k_y_nm_per_rad, "model.k_y_nm_per_rad", "N m/rad");
  check.non_negative(model.b_x_nms_per_rad, "model.b_x_nms_per_rad", "N m s/rad");
  check.non_negative(model.b_y_nms_per_rad, "model.b_y_nms_per_rad", "N m s/rad");
  check.positive(model.m_s_kg, "model.m_s_kg", "kg");
  check.non_negative(model.h_s_m, "model.h_s_m", "m");
  check.positive(gravity_mps2, "gravity_mps2", "m/s^2");
  check.require(mag_world_ut.allFinite() && mag_world_ut.norm() >= 1.0, "mag_world_ut",
                "a finite field of at least 1 uT [east, north, up]");
  check.require(mag_world_ut.head<2>().norm() >= 1e-3 * mag_world_ut.norm(), "mag_world_ut",
                "not vertical (no heading reference)");
  check.positive(static_yaw_rate_max_rps, "switching.static_yaw_rate_max_rps", "rad/s");
  check.positive(static_speed_max_mps, "switching.static_speed_max_mps", "m/s");
  check.non_negative(q_roll_rad2_per_s, "ekf.q_roll_rad2_per_s", "rad^2/s");
  check.non_negative(q_pitch_rad2_per_s, "ekf.q_pitch_rad2_per_s", "rad^2/s");
  check.non_negative(q_yaw_rad2_per_s, "ekf.q_yaw_rad2_per_s", "rad^2/s");
  check.require(r_mag_ut2.allFinite() && (r_mag_ut2.array() > 0.0).all(), "ekf.r_mag_ut2",
                "three finite values > 0 (uT^2)");
  check.positive(initial_var_angle_rad2, "ekf.initial_var_angle_rad2", "rad^2");
  check.positive(initial_var_rate_rad2ps2, "ekf.initial_var_rate_rad2ps2", "rad^2/s^2");
  check.positive(max_dt_s, "max_dt_s", "s");
  check.positive(max_yaw_rate_rps, "limits.max_yaw_rate_rps", "rad/s");
  check.positive(max_accel_mps2, "limits.max_accel_mps2", "m/s^2");
  check.positive(max_mag_ut, "limits.max_mag_ut", "uT");
  check.require(mag_norm_tolerance > 0.0 && mag_norm_tolerance < 1.0, "mag_norm_tolerance", "in (0, 1) (relative)");
}

Eigen::Matrix3d body_world_from_euler(double roll_rad, double pitch_rad, double yaw_rad) {
  return quat_from_euler_zyx(roll_rad, pitch_rad, yaw_rad).toRotationMatrix().transpose();  // (1)
}

Eigen::Vector3d euler_from_body_world(const Eigen::Matrix3d& r) {
  // (10) with 1-based indices R(2,3), R(3,3), R(1,3), R(1,2), R(1,1).
  double s = -r(0, 2);
  s = s > 1.0 ? 1.0 : (s < -1.0 ? -1.0 : s);
  return {std::atan2(r(1, 2), r(2, 2)), std::asin(s), std::atan2(r(0, 1), r(0, 0))};
}

bool triad_body_world(const Eigen::Vector3d& mag_body_ut, double accel_lat_g,
                      const Eigen::Vector3d& mag_world_ut, Eigen::Matrix3d& r_body_world) {
  if (!mag_body_ut.allFinite() || !std::isfinite(accel_lat_g)) {
    return false;
  }
  const double ay = accel_lat_g > 1.0 ? 1.0 : (accel_lat_g < -1.0 ? -1.0 : accel_lat_g);
  const Eigen::Vector3d g_m(0.0, ay, std::sqrt(1.0 - ay * ay));  // (7), world up seen in the body
  const Eigen::Vector3d g_ref(0.0, 0.0, 1.0);
  Eigen::Vector3d s1;
  Eigen::Vector3d s2;
  Eigen::Vector3d r1;
  Eigen::Vector3d r2;
  if (!safe_normalize(mag_body_ut, s1) || !safe_normalize(mag_body_ut.cross(g_m), s2, 1e-9) ||
      !safe_normalize(mag_world_ut, r1) || !safe_normalize(mag_world_ut.cross(g_ref), r2, 1e-9)) {
    return false;
  }
  const Eigen::Vector3d s3 = s1.cross(s2).normalized();  // (9)
  const Eigen::Vector3d r3 = r1.cross(r2).normalized();  // (9), r3 from r (the print repeats s)
  Eigen::Matrix3d s;
  Eigen::Matrix3d rr;
  s << s1, s2, s3;
  rr << r1, r2, r3;
  r_body_world = s * rr.transpose();  // (9)
  return true;
}

VehicleEstimator::VehicleEstimator(const VehicleParams& params) : params_(params) {
  params_.validate();
  limits_.max_dt_s = params_.max_dt_s;
  limits_.max_gyro_rps = params_.max_yaw_rate_rps;
  limits_.max_accel_mps2 = params_.max_accel_mps2;
  limits_.max_mag_ut = params_.max_mag_ut;
  limits_.min_accel_norm_mps2 = 0.0;  // a_x = a_y = 0 is a vehicle at rest on level ground
  reset();
}

void VehicleEstimator::reset() {
  s_ = VehicleEstimatorState{};
}

void VehicleEstimator::ekf_init(const Eigen::Vector3d& euler) {
  s_.x << euler(0), 0.0, euler(1), 0.0, euler(2);
  s_.p.setZero();
  s_.p.diagonal() << params_.initial_var_angle_rad2, params_.initial_var_rate_rad2ps2,
      params_.initial_var_angle_rad2, params_.initial_var_rate_rad2ps2, params_.initial_var_angle_rad2;
  s_.ekf_init = true;
}

void VehicleEstimator::ekf_predict(double a_x, double a_y, double r, double dt_s) {
  const VehicleModelParams& m = params_.model;
  const double phi = s_.x(0);
  const double theta = s_.x(2);
  const double sp = std::sin(phi);
  const double cp = std::cos(phi);
  const double st = std::sin(theta);
  const double ct = std::cos(theta);
  const double mh = m.m_s_kg * m.h_s_m;
  Vector5 f;  // (11)
  f << s_.x(1) + cp * st * r,
      (-m.k_x_nm_per_rad * phi - m.b_x_nms_per_rad * s_.x(1) + mh * a_y) / m.i_x_kgm2,
      s_.x(3) - sp * r,
      (-m.k_y_nm_per_rad * theta - m.b_y_nms_per_rad * s_.x(3) - mh * a_x) / m.i_y_kgm2,
      cp * ct * r;
  Matrix5 j = Matrix5::Zero();  // J_f_x
  j(0, 0) = -sp * st * r;
  j(0, 1) = 1.0;
  j(0, 2) = cp * ct * r;
  j(1, 0) = -m.k_x_nm_per_rad / m.i_x_kgm2;
  j(1, 1) = -m.b_x_nms_per_rad / m.i_x_kgm2;
  j(2, 0) = -cp * r;
  j(2, 3) = 1.0;
  j(3, 2) = -m.k_y_nm_per_rad / m.i_y_kgm2;
  j(3, 3) = -m.b_y_nms_per_rad / m.i_y_kgm2;
  j(4, 0) = -sp * ct * r;
  j(4, 2) = -cp * st * r;
  const Matrix5 fm = Matrix5::Identity() + j * dt_s;
  s_.x += f * dt_s;
  s_.x(4) = wrap_angle(s_.x(4));
  Vector5 q;
  q << params_.q_roll_rad2_per_s, 0.0, params_.q_pitch_rad2_per_s, 0.0, params_.q_yaw_rad2_per_s;  // (13)
  s_.p = fm * s_.p * fm.transpose();
  s_.p.diagonal() += q * dt_s;
  s_.p = 0.5 * (s_.p + s_.p.transpose());
}

void VehicleEstimator::ekf_correct(const Eigen::Vector3d& mag_ut) {
  const double phi = s_.x(0);
  const double theta = s_.x(2);
  const double psi = s_.x(4);
  // R = Rx(phi)^T Ry(theta)^T Rz(psi)^T = Rx(-phi) Ry(-theta) Rz(-psi); d/da R(-a) = -[e x] R(-a).
  const Eigen::Matrix3d rx = Eigen::AngleAxisd(-phi, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Matrix3d ry = Eigen::AngleAxisd(-theta, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Matrix3d rz = Eigen::AngleAxisd(-psi, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d& h_w = params_.mag_world_ut;
  const Eigen::Vector3d v_z = rz * h_w;
  const Eigen::Vector3d v_y = ry * v_z;
  const Eigen::Vector3d pred = rx * v_y;  // (12)
  Eigen::Matrix<double, 3, 5> hm = Eigen::Matrix<double, 3, 5>::Zero();  // J_B_x
  hm.col(0) = -skew(Eigen::Vector3d::UnitX()) * pred;
  hm.col(2) = rx * (-skew(Eigen::Vector3d::UnitY()) * v_y);
  hm.col(4) = rx * ry * (-skew(Eigen::Vector3d::UnitZ()) * v_z);
  const Eigen::Matrix3d rm = params_.r_mag_ut2.asDiagonal();  // (13)
  const Eigen::Matrix3d s = hm * s_.p * hm.transpose() + rm;
  const Eigen::Matrix<double, 5, 3> k = s_.p * hm.transpose() * s.inverse();
  s_.x += k * (mag_ut - pred);
  s_.x(4) = wrap_angle(s_.x(4));
  const Matrix5 ikh = Matrix5::Identity() - k * hm;
  s_.p = ikh * s_.p * ikh.transpose() + k * rm * k.transpose();  // Joseph form
  s_.p = 0.5 * (s_.p + s_.p.transpose());
}

void VehicleEstimator::set_output(const Eigen::Vector3d& euler, bool from_triad) {
  s_.est.roll_rad = euler(0);
  s_.est.pitch_rad = euler(1);
  s_.est.yaw_rad = wrap_angle(euler(2));
  s_.est.q_world_body = quat_from_euler_zyx(euler(0), euler(1), euler(2));
  s_.est.from_triad = from_triad;
  s_.est.valid = true;
}

VehicleSample vehicle_sample_from_imu(const ImuSample& imu, bool has_speed, double speed_mps) {
  VehicleSample v;
  v.stamp_ns = imu.stamp_ns;
  v.accel_lon_mps2 = imu.accel_mps2.x();
  v.accel_lat_mps2 = imu.accel_mps2.y();
  v.yaw_rate_rps = imu.gyro_rps.z();
  v.mag_ut = imu.mag_ut;
  v.has_mag = imu.has_mag;
  v.speed_mps = speed_mps;
  v.has_speed = has_speed;
  return v;
}

// not split: one filter step in the paper's order (sample checks, static test, TRIAD or EKF predict
// and correct, report); the state it updates is read top to bottom.
bool VehicleEstimator::update(const VehicleSample& s) {
  // The shared check on the signals as an IMU sample: gyro [0, 0, r], accel [a_x, a_y, 0], B.
  ImuSample imu;
  imu.stamp_ns = s.stamp_ns;
  imu.gyro_rps = Eigen::Vector3d(0.0, 0.0, s.yaw_rate_rps);
  imu.accel_mps2 = Eigen::Vector3d(s.accel_lon_mps2, s.accel_lat_mps2, 0.0);
  imu.mag_ut = s.mag_ut;
  imu.has_gyro = imu.has_accel = true;
  imu.has_mag = s.has_mag;
  const SampleCheck c = check_imu_sample(imu, s_.have_stamp ? s_.last_stamp_ns : -1, limits_, s_.rejects.samples,
                                         params_.use_magnetometer);
  if (s_.anchor.reanchor(c, s.stamp_ns, limits_.max_dt_s)) {
    s_.last_stamp_ns = s.stamp_ns;  // restart time after a confirmed jump; the state is kept
  }
  if (!c.accept) {
    reject_sample(to_string(c.reject));
    return false;
  }
  const double dt_s = c.dt_s;
  s_.last_stamp_ns = s.stamp_ns;

  if (s.has_speed && std::isfinite(s.speed_mps) && s.speed_mps >= 0.0) {
    s_.last_speed_mps = s.speed_mps;
    s_.speed.mark_fused(s.stamp_ns);
  } else {
    ++s_.rejects.bad_speed;
    if (s.has_speed) {
      s_.speed.mark_rejected("bad_speed");
    } else {
      s_.speed.mark_not_available("no_sample");
    }
  }
  bool mag_ok = c.mag_ok;
  if (!mag_ok) {
    if (c.mag_reject != RejectReason::kCount) {
      s_.mag.mark_rejected(to_string(c.mag_reject));
    } else {
      if (params_.use_magnetometer != MagnetometerUse::kOff) {
        ++s_.rejects.missing_mag;  // not when switched off (use_magnetometer: false)
      }
      s_.mag.mark_not_available(c.mag_absent);
    }
  } else {
    // The disturbance test as a gate: |B| - |H| against tolerance |H| (uT).
    const double h_ut = params_.mag_world_ut.norm();
    const double tol_ut = params_.mag_norm_tolerance * h_ut;
    s_.mag.set_innovation(InnovationVector::Constant(1, s.mag_ut.norm() - h_ut),
                        InnovationVector::Constant(1, tol_ut * tol_ut));
    if (s_.mag.test_ratio > 1.0) {
      ++s_.rejects.disturbed_mag;
      mag_ok = false;
      s_.mag.mark_rejected("disturbed_mag");
    }
  }

  const bool is_static = std::abs(s.yaw_rate_rps) < params_.static_yaw_rate_max_rps &&
                         s_.last_speed_mps < params_.static_speed_max_mps;
  s_.est.is_static = is_static;
  s_.est.stamp_ns = s.stamp_ns;

  Eigen::Vector3d mag_in = s.mag_ut;
  double ay_in = s.accel_lat_mps2;
  if (!is_static) {
    s_.static_count = 0;
    s_.static_mag_sum.setZero();
    s_.static_ay_sum = 0.0;
  } else if (params_.static_average && mag_ok) {
    s_.static_mag_sum += s.mag_ut;
    s_.static_ay_sum += s.accel_lat_mps2;
    ++s_.static_count;
    mag_in = s_.static_mag_sum / static_cast<double>(s_.static_count);
    ay_in = s_.static_ay_sum / static_cast<double>(s_.static_count);
  }
  Eigen::Vector3d triad_euler(0.0, 0.0, 0.0);
  bool triad_ok = false;
  if (mag_ok) {
    Eigen::Matrix3d r;
    triad_ok = triad_body_world(mag_in, ay_in / params_.gravity_mps2, params_.mag_world_ut, r);
    if (triad_ok) {
      triad_euler = euler_from_body_world(r);
    }
  }

  const bool propagate = s_.have_stamp && s_.ekf_init;
  s_.have_stamp = true;
  const VehicleMode mode = params_.mode;
  const bool use_triad = mode == VehicleMode::kTriad || (mode == VehicleMode::kSwitched && is_static);
  if (use_triad) {
    if (triad_ok) {
      set_output(triad_euler, true);
      ekf_init(triad_euler);  // the EKF restarts from the static solution
    }
    // else: no usable magnetometer; the last output is held (static: the vehicle does not turn).
  } else if (s_.ekf_init) {
    if (propagate) {
      ekf_predict(s_.prev_ax, s_.prev_ay, s_.prev_r, dt_s);
    }
    if (mag_ok) {
      ekf_correct(s.mag_ut);
    }
    set_output(Eigen::Vector3d(s_.x(0), s_.x(2), s_.x(4)), false);
  } else if (triad_ok) {
    ekf_init(triad_euler);  // first fix: the EKF starts from TRIAD
    set_output(triad_euler, true);
  }

  // What the step used: TRIAD uses a_y and B; the EKF propagates with a_x, a_y, r and corrects
  // with B (after the first fix).
  const bool ekf_ran = !use_triad && s_.ekf_init;
  if (ekf_ran && propagate) {
    s_.yaw_rate.mark_fused(s.stamp_ns);
  } else {
    s_.yaw_rate.mark_not_available(use_triad ? "static_triad" : "no_previous_sample");
  }
  const bool fixed = use_triad ? triad_ok : (ekf_ran || triad_ok);
  if (fixed) {
    s_.accel.mark_fused(s.stamp_ns);
  } else {
    s_.accel.mark_not_available("no_mag_fix");
  }
  if (mag_ok) {
    if (fixed) {
      s_.mag.mark_fused(s.stamp_ns);
    } else {
      s_.mag.mark_rejected("triad_degenerate");
    }
  }

  s_.prev_ax = s.accel_lon_mps2;
  s_.prev_ay = s.accel_lat_mps2;
  s_.prev_r = s.yaw_rate_rps;
  if (!healthy()) {
    reset_unhealthy();
    return false;
  }
  return true;
}

bool VehicleEstimator::healthy() {
  const bool full = s_.health.full_due();
  return all_finite(s_.x, s_.est.q_world_body.coeffs(), s_.static_mag_sum, s_.static_ay_sum) &&
         covariance_ok(s_.p, full);
}

void VehicleEstimator::reset_unhealthy() {
  using S = VehicleEstimatorState;
  reset_keeping(s_, [this] { reset(); }, &S::rejects, &S::yaw_rate, &S::accel, &S::mag, &S::speed);
  reject_sample(kStateResetReason);
}

void VehicleEstimator::reject_sample(const char* why) {
  for (SourceReport* r : {&s_.yaw_rate, &s_.accel, &s_.mag, &s_.speed}) {
    r->mark_rejected(why);
  }
}

}  // namespace poise
