// The attitude-math layer: every filter uses these helpers instead of hand-rolling its own.
//
// Conventions (see types.h): Hamilton quaternions, `q_a_b` rotates vectors from frame b into frame
// a (v_a = q_a_b * v_b), stored/exchanged as [w, x, y, z]. Rotation vectors (axis * angle, rad)
// are the SO(3) logarithm. Euler angles are intrinsic Z-Y-X (yaw, pitch, roll): R = Rz(yaw)
// Ry(pitch) Rx(roll). Jacobians are named J_out_in.
//
// Everything here is header-only and allocation-free so the filters stay inlinable (the parallel
// KF budget is a few hundred ns per sample).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cmath>

namespace poise {

/// Small-angle threshold (rad) below which series expansions replace trigonometric formulas.
inline constexpr double kSmallAngleRad = 1e-8;
inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kDegPerRad = 180.0 / kPi;
inline constexpr double kRadPerDeg = kPi / 180.0;
/// Standard gravity, m/s^2.
inline constexpr double kStandardGravityMps2 = 9.80665;

// ---------------------------------------------------------------- numerical helpers
/// True when every coefficient is finite (no NaN, no Inf).
template <typename Derived>
inline bool all_finite(const Eigen::MatrixBase<Derived>& m) {
  return m.allFinite();
}

/// Normalises `v` into `out` when its norm exceeds `min_norm`; returns false (and leaves `out`
/// untouched) for zero, tiny or non-finite vectors.
inline bool safe_normalize(const Eigen::Vector3d& v, Eigen::Vector3d& out, double min_norm = 1e-12) {
  const double n = v.norm();
  if (!std::isfinite(n) || n <= min_norm) {
    return false;
  }
  out = v / n;
  return true;
}

/// Wraps an angle to (-pi, pi].
inline double wrap_angle(double a_rad) {
  double w = std::fmod(a_rad + kPi, 2.0 * kPi);
  if (w <= 0.0) {
    w += 2.0 * kPi;
  }
  return w - kPi;
}

/// Angle between two non-zero vectors, rad in [0, pi] (atan2 form: accurate near 0 and pi).
inline double angle_between_vectors(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// ---------------------------------------------------------------- skew matrices
/// [v x]: skew(v) * u == v.cross(u).
inline Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return s;
}

/// Inverse of skew(): the vector of a (nearly) skew-symmetric matrix, antisymmetric part used.
inline Eigen::Vector3d unskew(const Eigen::Matrix3d& s) {
  return 0.5 * Eigen::Vector3d(s(2, 1) - s(1, 2), s(0, 2) - s(2, 0), s(1, 0) - s(0, 1));
}

// ---------------------------------------------------------------- quaternion storage
/// Quaternion from [w, x, y, z].
inline Eigen::Quaterniond quat_from_wxyz(const std::array<double, 4>& wxyz) {
  return Eigen::Quaterniond(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
}
inline Eigen::Quaterniond quat_from_wxyz(const Eigen::Vector4d& wxyz) {
  return Eigen::Quaterniond(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
}
inline Eigen::Quaterniond quat_from_wxyz(double w, double x, double y, double z) {
  return Eigen::Quaterniond(w, x, y, z);
}
/// [w, x, y, z] of a quaternion.
inline std::array<double, 4> quat_to_wxyz(const Eigen::Quaterniond& q) {
  return {q.w(), q.x(), q.y(), q.z()};
}
inline Eigen::Vector4d quat_to_wxyz_vec(const Eigen::Quaterniond& q) {
  return Eigen::Vector4d(q.w(), q.x(), q.y(), q.z());
}

/// Unit quaternion with the sign convention w >= 0 (q and -q are the same rotation; the canonical
/// one is published). Returns identity for zero / non-finite input.
inline Eigen::Quaterniond quat_canonical(const Eigen::Quaterniond& q) {
  const double n = q.coeffs().norm();
  if (!std::isfinite(n) || n < 1e-12) {
    return Eigen::Quaterniond::Identity();
  }
  Eigen::Quaterniond out(q.coeffs() / n);
  if (out.w() < 0.0) {
    out.coeffs() = -out.coeffs();
  }
  return out;
}

/// `q` or `-q`, whichever is closer to `ref` (4-D dot product >= 0). For innovations and averages.
inline Eigen::Quaterniond quat_align_sign(const Eigen::Quaterniond& q, const Eigen::Quaterniond& ref) {
  if (q.coeffs().dot(ref.coeffs()) < 0.0) {
    return Eigen::Quaterniond(-q.coeffs());
  }
  return q;
}

// ---------------------------------------------------------------- exp / log
/// Unit quaternion of a rotation vector (rad): exp(phi / 2) in quaternion algebra.
inline Eigen::Quaterniond quat_exp(const Eigen::Vector3d& phi) {
  const double t2 = phi.squaredNorm();
  if (t2 < 0.05 * 0.05) {
    // Series in b^2 = (|phi| / 2)^2 (per-sample rotations need no trig): cos b and sin(b) / |phi|
    // to the b^6 term, truncation below 1e-17 for |phi| < 0.05 rad, so the result is unit to rounding.
    const double b2 = 0.25 * t2;
    const double c = 1.0 - b2 * (1.0 / 2.0 - b2 * (1.0 / 24.0 - b2 / 720.0));
    const double s = 0.5 * (1.0 - b2 * (1.0 / 6.0 - b2 * (1.0 / 120.0 - b2 / 5040.0)));
    return Eigen::Quaterniond(c, s * phi.x(), s * phi.y(), s * phi.z());
  }
  const double angle = std::sqrt(t2);
  const double s = std::sin(0.5 * angle) / angle;
  return Eigen::Quaterniond(std::cos(0.5 * angle), s * phi.x(), s * phi.y(), s * phi.z());
}

/// Rotation vector (rad) of a unit quaternion, angle in [0, pi] (the shorter rotation).
inline Eigen::Vector3d quat_log(const Eigen::Quaterniond& q_in) {
  const Eigen::Quaterniond q = quat_canonical(q_in);
  const Eigen::Vector3d v = q.vec();
  const double vn = v.norm();
  if (vn < 1e-12) {
    return 2.0 * v;  // first order: phi = 2 v / w, w ~ 1
  }
  const double angle = 2.0 * std::atan2(vn, q.w());
  return v * (angle / vn);
}

/// Rotation matrix of a rotation vector (Rodrigues: I + a [phi x] + b [phi x]^2 with
/// a = sin(t)/t, b = (1 - cos(t))/t^2; series below 0.05 rad, so per-sample steps need no trig).
inline Eigen::Matrix3d rot_exp(const Eigen::Vector3d& phi) {
  const double t2 = phi.squaredNorm();
  double a;
  double b;
  if (t2 < 0.05 * 0.05) {
    a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0;
    b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0;
  } else {
    const double t = std::sqrt(t2);
    a = std::sin(t) / t;
    b = (1.0 - std::cos(t)) / t2;
  }
  // [phi x]^2 = phi phi^T - |phi|^2 I
  Eigen::Matrix3d r = b * (phi * phi.transpose());
  r.diagonal().array() += 1.0 - b * t2;
  const Eigen::Vector3d av = a * phi;
  r(0, 1) -= av.z();
  r(1, 0) += av.z();
  r(0, 2) += av.y();
  r(2, 0) -= av.y();
  r(1, 2) -= av.x();
  r(2, 1) += av.x();
  return r;
}

/// Rotation vector of a rotation matrix (via the quaternion, robust near pi).
inline Eigen::Vector3d rot_log(const Eigen::Matrix3d& r) {
  return quat_log(Eigen::Quaterniond(r));
}

/// Right Jacobian of SO(3): exp(phi + d) ~= exp(phi) exp(J_r(phi) d).
inline Eigen::Matrix3d so3_right_jacobian(const Eigen::Vector3d& phi) {
  const double a = phi.norm();
  const Eigen::Matrix3d s = skew(phi);
  if (a < 1e-6) {
    return Eigen::Matrix3d::Identity() - 0.5 * s + s * s / 6.0;
  }
  const double a2 = a * a;
  return Eigen::Matrix3d::Identity() - (1.0 - std::cos(a)) / a2 * s +
         (a - std::sin(a)) / (a2 * a) * s * s;
}

/// Inverse of the right Jacobian: log(exp(phi) exp(d)) ~= phi + J_r^-1(phi) d.
inline Eigen::Matrix3d so3_right_jacobian_inv(const Eigen::Vector3d& phi) {
  const double a = phi.norm();
  const Eigen::Matrix3d s = skew(phi);
  if (a < 1e-6) {
    return Eigen::Matrix3d::Identity() + 0.5 * s + s * s / 12.0;
  }
  const double a2 = a * a;
  return Eigen::Matrix3d::Identity() + 0.5 * s +
         (1.0 / a2 - (1.0 + std::cos(a)) / (2.0 * a * std::sin(a))) * s * s;
}

/// Jacobian of v_rot = R(q) v with respect to a body-frame (right) perturbation q exp(d):
/// J_vrot_d = -R(q) [v x].
inline Eigen::Matrix3d J_rotate_right_perturbation(const Eigen::Quaterniond& q,
                                                   const Eigen::Vector3d& v) {
  return -q.toRotationMatrix() * skew(v);
}

/// Body-frame strapdown step: q_world_body(k) = q_world_body(k-1) (x) exp(omega_body dt).
inline Eigen::Quaterniond quat_integrate_body_rate(const Eigen::Quaterniond& q_world_body,
                                                   const Eigen::Vector3d& omega_body_rps,
                                                   double dt_s) {
  return (q_world_body * quat_exp(omega_body_rps * dt_s)).normalized();
}

// ---------------------------------------------------------------- Euler angles
/// Roll, pitch, yaw (rad) of q_world_body, intrinsic Z-Y-X; yaw in (-pi, pi] counter-clockwise
/// from world x (east in ENU), pitch in [-pi/2, pi/2] (clamped asin argument, atan2 elsewhere).
inline Eigen::Vector3d euler_zyx_from_quat(const Eigen::Quaterniond& q_in) {
  const Eigen::Quaterniond q = q_in.normalized();
  const double w = q.w();
  const double x = q.x();
  const double y = q.y();
  const double z = q.z();
  const double roll = std::atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y));
  double sp = 2.0 * (w * y - z * x);
  sp = sp > 1.0 ? 1.0 : (sp < -1.0 ? -1.0 : sp);
  const double pitch = std::asin(sp);
  const double yaw = std::atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
  return {roll, pitch, yaw};
}

/// q_world_body of roll, pitch, yaw (rad), intrinsic Z-Y-X.
inline Eigen::Quaterniond quat_from_euler_zyx(double roll_rad, double pitch_rad, double yaw_rad) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()) *
                            Eigen::AngleAxisd(pitch_rad, Eigen::Vector3d::UnitY()) *
                            Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitX()));
}

/// The attitude every filter starts from without a magnetometer (6-axis): the tilt of `up_body`
/// (the world up axis seen in the body, e.g. the accelerometer at rest) and ZYX yaw 0, i.e. the
/// body's x axis in the east-up plane. Heading is not observable without a magnetometer: yaw 0 is
/// a convention, the same in every filter. Identity for a zero vector.
inline Eigen::Quaterniond quat_tilt_yaw0(const Eigen::Vector3d& up_body) {
  if (!(up_body.norm() > 0.0)) {
    return Eigen::Quaterniond::Identity();
  }
  const double roll = std::atan2(up_body.y(), up_body.z());
  const double pitch = std::atan2(-up_body.x(), std::hypot(up_body.y(), up_body.z()));
  return quat_from_euler_zyx(roll, pitch, 0.0);
}

// ---------------------------------------------------------------- constructions
/// The shortest rotation q with q * from == to (directions only; inputs need not be unit).
/// Antiparallel inputs rotate by pi about an axis orthogonal to `from`. Identity for zero input.
inline Eigen::Quaterniond quat_from_two_vectors(const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  Eigen::Vector3d a;
  Eigen::Vector3d b;
  if (!safe_normalize(from, a) || !safe_normalize(to, b)) {
    return Eigen::Quaterniond::Identity();
  }
  const double d = a.dot(b);
  if (d < -1.0 + 1e-12) {
    // pi rotation about any axis orthogonal to a.
    Eigen::Vector3d axis = a.cross(Eigen::Vector3d::UnitX());
    if (axis.squaredNorm() < 1e-6) {
      axis = a.cross(Eigen::Vector3d::UnitY());
    }
    axis.normalize();
    return Eigen::Quaterniond(0.0, axis.x(), axis.y(), axis.z());
  }
  const Eigen::Vector3d c = a.cross(b);
  return Eigen::Quaterniond(1.0 + d, c.x(), c.y(), c.z()).normalized();
}

/// `v` rotated by the shortest rotation that takes unit `from` to unit `to` (= quat_from_two_vectors
/// (from, to) * v for unit inputs, without a square root): R v = d v + c x v + c (c . v) / (1 + d),
/// c = from x to, d = from . to. Requires from . to > -1 + 1e-9 (not anti-parallel); returns v
/// unchanged otherwise.
inline Eigen::Vector3d rotate_by_shortest(const Eigen::Vector3d& from_unit, const Eigen::Vector3d& to_unit,
                                          const Eigen::Vector3d& v) {
  const double d = from_unit.dot(to_unit);
  if (!(d > -1.0 + 1e-9)) {
    return v;
  }
  const Eigen::Vector3d c = from_unit.cross(to_unit);
  return d * v + c.cross(v) + c * (c.dot(v) / (1.0 + d));
}

/// Rotation matrix R_body_world whose columns are the world axes seen in the body frame,
/// built from the world "up" axis and a second, non-parallel world reference (both in body
/// coordinates), world x along the horizontal part of `forward_body` (paper 000 eq. 2 and text:
/// Y = normalise(Z x X'), X = Y x Z). Returns false when the inputs are (anti)parallel or degenerate.
inline bool body_world_axes_from_up_forward(const Eigen::Vector3d& up_body,
                                            const Eigen::Vector3d& forward_body,
                                            Eigen::Matrix3d& r_body_world) {
  Eigen::Vector3d z;
  Eigen::Vector3d y;
  if (!safe_normalize(up_body, z) || !safe_normalize(z.cross(forward_body), y, 1e-9)) {
    return false;
  }
  r_body_world.col(0) = y.cross(z);
  r_body_world.col(1) = y;
  r_body_world.col(2) = z;
  return true;
}

/// Rotation from the NWU world (x north, y west, z up) to ENU: x_ENU = -y_NWU, y_ENU = x_NWU.
inline Eigen::Matrix3d rot_enu_nwu() {
  Eigen::Matrix3d r;
  r << 0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0;
  return r;
}
/// The same rotation as a quaternion: +90 deg about z.
inline Eigen::Quaterniond quat_enu_nwu() {
  const double s = std::sqrt(0.5);
  return Eigen::Quaterniond(s, 0.0, 0.0, s);
}

// ---------------------------------------------------------------- comparisons
/// Rotation angle (rad, [0, pi]) of a^-1 b; sign-invariant (q == -q).
inline double quat_angle_between(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  const Eigen::Quaterniond d = a.conjugate() * b;
  return 2.0 * std::atan2(d.vec().norm(), std::abs(d.w()));
}

/// Heading (rotation about world z) and inclination parts of a world-frame error quaternion
/// q_err = q_est (x) conj(q_ref), rad. Heading = 2 atan(|z/w|), inclination = 2 acos(sqrt(w^2+z^2))
/// (the BROAD benchmark decomposition).
struct HeadingInclination {
  double heading_rad = 0.0;
  double inclination_rad = 0.0;
};
inline HeadingInclination heading_inclination_of_world_error(const Eigen::Quaterniond& q_err_in) {
  const Eigen::Quaterniond q = q_err_in.normalized();
  HeadingInclination out;
  out.heading_rad = 2.0 * std::atan(std::abs(q.z() / q.w()));
  double c = std::sqrt(q.w() * q.w() + q.z() * q.z());
  c = c > 1.0 ? 1.0 : c;
  out.inclination_rad = 2.0 * std::acos(c);
  return out;
}

}  // namespace poise
