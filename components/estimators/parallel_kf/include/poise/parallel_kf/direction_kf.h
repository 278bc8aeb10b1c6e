// DirectionKf: the linear Kalman filter shared by both halves of the parallel KF (paper 000).
//
// Notation (paper 000, J. K. Lee 2016; readings in docs ESTIMATORS.md section 2)
//   S        sensor (body) frame; every vector in this filter is expressed in S.
//   u        unit direction of a world reference seen in S:  KF1: u = sZ (world up),
//            KF2: u = sX' (direction of the local magnetic field, dip included).
//   e        additive perturbation of the measurement:       KF1: e = sa (external acceleration,
//            m/s^2), KF2: e = sd (magnetic disturbance, uT).
//   k        reference magnitude: KF1 k = g (m/s^2), KF2 k = m (field magnitude, uT).
//   s        measurement: KF1 s_A (accelerometer), KF2 s_M (magnetometer).    (1a), (1b)
//   w        gyro signal s_G at k-1 (rad/s), h = dt (s).
//   x = [u; e],   z = s = k u + e + n                                       (4), (8), (3a), (3b)
//   F = [[I - h[w x], 0], [0, c I]]                                          (7a), (11a)
//   Q = blkdiag(h^2 sigma_G^2 [u x][u x]^T,  c^2/3 |e_{k-1}|^2 I + sigma_s^2 I)  (7c-e), (11c-e)
//   H = [k I | I],  M = sigma_s^2 I                                          (7f,h), (11f,h)
// Options beyond the paper (all off in the paper configuration): exact rotation of u by
// exp(-h w) instead of (I - h[w x]) (first order, grows |u|), renormalisation of u after each
// step, c given at a reference rate and converted to the actual step (c^(rate * h)), and an extra
// gyro-error process noise (bias drift) on u.
//
// The tangent form (exact rotation, renormalised u, c = 0: the default's KF1 and KF2). u is a unit
// direction, so its error lies across u; Q11 (above) is isotropic across u and zero along it, M is
// isotropic, the start is var_u I, and a rotation carries u and P11 alike. P11 then keeps the form
// alpha (I - u u^T) + beta u u^T under the prediction, and the closed-form correction (S = k^2 P11 +
// (d + r) I shares P11's eigenvectors) maps it to the same form with alpha' = (d + r) alpha /
// (k^2 alpha + d + r) (beta likewise). The filter keeps the two numbers instead of the 3x3 matrix:
// what is across u is alpha, what is along it beta (only the start's share, which the corrections
// shrink). Approximation: the correction moves u by the step's correction angle while the
// posterior's eigenvectors stay with the prior's u; the form takes them along with u (as the
// renormalisation takes u's length). Any other case keeps the full 6x6 P.
#pragma once

#include "poise/core/attitude.h"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace poise {

/// Parameters of one DirectionKf. Units depend on the instance (see the notation block).
struct DirectionKfParams {
  double sigma_gyro_rps = 0.05 * kRadPerDeg;  ///< sigma_G: gyro noise std, rad/s (Table 1: 0.05 deg/s)
  double sigma_meas = 0.04;    ///< sigma_A or sigma_M: measurement noise std (m/s^2 or uT)
  double c = 0.1;              ///< c_a or c_d: first-order Markov coefficient of e, in [0, 1)
  /// When > 0, `c` is the coefficient per step at this rate (Hz) and the step coefficient is
  /// c^(c_rate_hz * h) (the paper's 0.1 is given at 100 Hz). 0 = use `c` per step as printed.
  double c_rate_hz = 0.0;
  bool exact_rotation = false;  ///< propagate u with exp(-h w) (exact) instead of I - h[w x]
  bool renormalize = false;     ///< renormalise u to unit length after each step
  /// Additional gyro error std (rad/s, e.g. residual bias) added to sigma_G in Q11 as
  /// h^2 (sigma_G^2 + sigma_bias^2) [u x][u x]^T. 0 = paper.
  double sigma_gyro_extra_rps = 0.0;
};

/// The 6-state linear KF of the notation block. Pure math: the caller validates inputs.
class DirectionKf {
 public:
  using Matrix6 = Eigen::Matrix<double, 6, 6>;

  DirectionKf() = default;
  explicit DirectionKf(const DirectionKfParams& p) : p_(p) {}

  void set_params(const DirectionKfParams& p) {
    if (tangent()) {
      materialize();  // the new parameters may not keep the tangent form: P written in full
    }
    p_ = p;
    cached_h_ = -1.0;
  }
  [[nodiscard]] const DirectionKfParams& params() const { return p_; }

  /// Starts at direction `u` (normalised) with e = 0 and covariance diag(var_u I, var_e I).
  void reset(const Eigen::Vector3d& u, double var_u, double var_e) {
    layout_ = Layout::kFull;
    u_ = u.normalized();
    e_.setZero();
    p_mat_.setZero();
    p_mat_.topLeftCorner<3, 3>().diagonal().setConstant(var_u);
    p_mat_.bottomRightCorner<3, 3>().diagonal().setConstant(var_e);
  }

  /// Time update over h with gyro w (rad/s, already bias-corrected by the caller if wanted).
  void predict(const Eigen::Vector3d& w_rps, double h_s) {
    if (p_.exact_rotation) {
      predict_with_transition(rot_exp(-h_s * w_rps), h_s);  // u_k = R(h w)^T u_{k-1}
    } else {
      Eigen::Matrix3d a = -h_s * skew(w_rps);  // (5a), (7a): I - h[s_G x]
      a.diagonal().array() += 1.0;
      predict_with_transition(a, h_s);
    }
  }

  /// Time update with a given direction transition `a` (I - h[w x] or exp(-h w)) over h.
  void predict_with_transition(const Eigen::Matrix3d& a, double h_s) {
    const double c = step_c(h_s);
    const double sg2 = p_.sigma_gyro_rps * p_.sigma_gyro_rps +
                       p_.sigma_gyro_extra_rps * p_.sigma_gyro_extra_rps;
    // Q11 = h^2 sigma^2 [u x][u x]^T = h^2 sigma^2 (|u|^2 I - u u^T)            (7d), (11d)
    const double qg = h_s * h_s * sg2;
    // (7e), (11e); with c = 0 exactly sigma^2 (e is finite: the state-health check)
    const double s2 = p_.sigma_meas * p_.sigma_meas;
    const double q22 = c == 0.0 ? s2 : c * c / 3.0 * e_.squaredNorm() + s2;
    if (c == 0.0 && p_.exact_rotation && p_.renormalize) {
      predict_tangent(a, qg, q22);
      return;
    }
    const Eigen::Vector3d u_prev = u_;

    u_.noalias() = a * u_prev;  // (5a), (9a)

    if (c != 0.0) {
      materialize();  // P12 and P22 are propagated below
    }
    Eigen::Matrix3d n11;
    n11.noalias() = a * p_mat_.topLeftCorner<3, 3>() * a.transpose();
    n11.noalias() -= qg * (u_prev * u_prev.transpose());
    n11.diagonal().array() += qg * u_prev.squaredNorm();
    p_mat_.topLeftCorner<3, 3>() = 0.5 * (n11 + n11.transpose());  // symmetric (a P a^T rounds unevenly)
    if (c == 0.0) {
      // e = 0, P12 = 0, P22 = q22 I exactly (which correct() then updates in closed form; the
      // blocks are written only when covariance() is asked)
      e_.setZero();
      d_ = q22;
      layout_ = Layout::kBlockDiagonal;
      return;
    }
    e_ *= c;  // (5b), (9b)
    const Eigen::Matrix3d p12 = p_mat_.topRightCorner<3, 3>();
    p_mat_.topRightCorner<3, 3>().noalias() = c * (a * p12);
    p_mat_.bottomLeftCorner<3, 3>() = p_mat_.topRightCorner<3, 3>().transpose();
    p_mat_.bottomRightCorner<3, 3>() *= c * c;
    p_mat_.bottomRightCorner<3, 3>().diagonal().array() += q22;
    layout_ = Layout::kFull;
  }

  /// Measurement update with z = k u + e + n (H = [k I | I], M = sigma^2 I). `extra_var` is added
  /// to M (0 for the paper). Returns the innovation z - H x (before the update).
  Eigen::Vector3d correct(const Eigen::Vector3d& z, double k, double extra_var = 0.0) {
    const Eigen::Vector3d innov = z - k * u_ - e_;
    // M is diagonal, so the batch update equals three sequential scalar updates (rows of
    // H = [k I | I]); this avoids the 3x3 inverse and the 6x3 gain products.
    const double r = p_.sigma_meas * p_.sigma_meas + extra_var;  // (7h), (11h)
    if (layout_ == Layout::kBlockDiagonal) {
      correct_decoupled(innov, k, r);
      return innov;
    }
    if (layout_ == Layout::kTangentPrior) {
      correct_tangent(innov, k, r);
      return innov;
    }
    materialize();
    Eigen::Matrix<double, 6, 1> x;
    x << u_, e_;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Matrix<double, 6, 1> pht = k * p_mat_.col(i) + p_mat_.col(3 + i);  // P h^T
      const double s = k * pht[i] + pht[3 + i] + r;                                    // h P h^T + r
      const double y = z[i] - (k * x[i] + x[3 + i]);
      const Eigen::Matrix<double, 6, 1> gain = pht / s;
      x.noalias() += gain * y;
      p_mat_.noalias() -= gain * pht.transpose();  // P - K h P
    }
    p_mat_ = 0.5 * (p_mat_ + p_mat_.transpose()).eval();
    u_ = x.head<3>();
    e_ = x.tail<3>();
    if (p_.renormalize) {
      u_.normalize();
    }
    return innov;
  }

  /// Inverse of a symmetric 3x3 matrix by its cofactors (six of them), exactly symmetric.
  static Eigen::Matrix3d symmetric_inverse(const Eigen::Matrix3d& m) {
    const double c00 = m(1, 1) * m(2, 2) - m(1, 2) * m(1, 2);
    const double c01 = m(0, 2) * m(1, 2) - m(0, 1) * m(2, 2);
    const double c02 = m(0, 1) * m(1, 2) - m(0, 2) * m(1, 1);
    const double c11 = m(0, 0) * m(2, 2) - m(0, 2) * m(0, 2);
    const double c12 = m(0, 1) * m(0, 2) - m(0, 0) * m(1, 2);
    const double c22 = m(0, 0) * m(1, 1) - m(0, 1) * m(0, 1);
    const double inv_det = 1.0 / (m(0, 0) * c00 + m(0, 1) * c01 + m(0, 2) * c02);
    Eigen::Matrix3d r;
    r << c00, c01, c02, c01, c11, c12, c02, c12, c22;
    return inv_det * r;
  }

  [[nodiscard]] const Eigen::Vector3d& u() const { return u_; }
  [[nodiscard]] const Eigen::Vector3d& e() const { return e_; }
  /// P, by value: after a prediction or correction with c = 0 only P11 is stored, and the other
  /// blocks are filled in here from what the update kept (the filter itself is not written, so
  /// concurrent readers are safe)
  [[nodiscard]] Matrix6 covariance() const {
    Matrix6 p = p_mat_;
    fill_blocks(p);
    return p;
  }
  /// P11, the direction's block, without writing the others
  [[nodiscard]] Eigen::Matrix3d direction_covariance() const {
    if (tangent()) {
      return tangent_matrix(alpha_, beta_);
    }
    return p_mat_.topLeftCorner<3, 3>();
  }
  /// v^T P11 v, the direction's variance along v (direction units^2 |v|^2)
  [[nodiscard]] double variance_along(const Eigen::Vector3d& v) const {
    if (tangent()) {
      const double along = v.dot(u_) / u_.squaredNorm() * v.dot(u_);
      return alpha_ * (v.squaredNorm() - along) + beta_ * along;
    }
    return v.dot(p_mat_.topLeftCorner<3, 3>() * v);
  }
  /// The diagonal of P without writing the blocks
  [[nodiscard]] Eigen::Matrix<double, 6, 1> covariance_diagonal() const {
    Eigen::Matrix<double, 6, 1> v;
    if (tangent()) {
      const Eigen::Vector3d uu = u_.cwiseAbs2() / u_.squaredNorm();
      v.head<3>() = (beta_ - alpha_) * uu.array() + alpha_;
      v.tail<3>().setConstant(d_);
      if (layout_ == Layout::kTangentPosterior) {
        v.tail<3>() -= (d_ * d_) * ((ib_ - ia_) * uu.array() + ia_).matrix();
      }
      return v;
    }
    v.head<3>() = p_mat_.diagonal().head<3>();
    if (layout_ == Layout::kBlockDiagonal) {
      v.tail<3>().setConstant(d_);
    } else if (layout_ == Layout::kDecoupledPosterior) {
      v.tail<3>() = ((-d_ * d_) * s_inv_.diagonal()).array() + d_;
    } else {
      v.tail<3>() = p_mat_.diagonal().tail<3>();
    }
    return v;
  }
  /// The per-sample health check's part: every variance of P finite and none negative (in the
  /// tangent form from its numbers, without building the diagonal)
  [[nodiscard]] bool variances_ok() const {
    if (tangent()) {
      const double p22 = layout_ == Layout::kTangentPosterior ? d_ - d_ * d_ * std::max(ia_, ib_) : d_;
      return std::isfinite(alpha_ + beta_ + d_ + ia_ + ib_) && std::min({alpha_, beta_, p22}) >= 0.0;
    }
    const Eigen::Matrix<double, 6, 1> v = covariance_diagonal();
    return v.allFinite() && v.minCoeff() >= 0.0;
  }
  /// Replaces u (e.g. after an external correction); the caller keeps it unit if it wants.
  void set_u(const Eigen::Vector3d& u) { u_ = u; }
  void set_e(const Eigen::Vector3d& e) {
    materialize();
    e_ = e;
  }

  /// The Markov coefficient for a step of h seconds.
  [[nodiscard]] double step_c(double h_s) const {
    if (p_.c_rate_hz > 0.0 && p_.c > 0.0) {
      if (h_s != cached_h_) {
        cached_h_ = h_s;
        cached_c_ = std::pow(p_.c, p_.c_rate_hz * h_s);
      }
      return cached_c_;
    }
    return p_.c;
  }

 private:
  [[nodiscard]] bool tangent() const {
    return layout_ == Layout::kTangentPrior || layout_ == Layout::kTangentPosterior;
  }
  /// x (I - u u^T) + y u u^T for the current u (normalised here)
  [[nodiscard]] Eigen::Matrix3d tangent_matrix(double x, double y) const {
    Eigen::Matrix3d m = ((y - x) / u_.squaredNorm()) * (u_ * u_.transpose());
    m.diagonal().array() += x;
    return m;
  }

  /// The prediction in the tangent form (notation): u_k = a u_{k-1}; Q11 = h^2 sigma^2 (|u|^2 I -
  /// u u^T) adds h^2 sigma^2 |u|^2 across u and nothing along it; e = 0, P12 = 0, P22 = q22 I.
  void predict_tangent(const Eigen::Matrix3d& a, double qg, double q22) {
    if (!tangent()) {  // from the full P (after reset(), set_e() or a full update): its two numbers
      materialize();
      const Eigen::Matrix3d p11 = p_mat_.topLeftCorner<3, 3>();
      beta_ = u_.dot(p11 * u_) / u_.squaredNorm();
      alpha_ = 0.5 * (p11.trace() - beta_);
    }
    const double n2 = u_.squaredNorm();
    const Eigen::Vector3d u_prev = u_;
    u_ = a.col(0) * u_prev[0] + a.col(1) * u_prev[1] + a.col(2) * u_prev[2];  // (5a), (9a)
    alpha_ += qg * n2;
    e_.setZero();
    d_ = q22;
    layout_ = Layout::kTangentPrior;
  }

  /// correct_decoupled() in the tangent form: S = k^2 P11 + (d + r) I has the eigenvalues
  /// s_a = k^2 alpha + d + r across u and s_b = k^2 beta + d + r along it, so with v = v_across +
  /// v_along: u += k (alpha / s_a v_across + beta / s_b v_along), e = d (v_across / s_a + v_along /
  /// s_b), alpha' = (d + r) alpha / s_a, beta' = (d + r) beta / s_b; P12 = -k d P11 S^-1 and P22 =
  /// d I - d^2 S^-1 are kept as the two inverses.
  void correct_tangent(const Eigen::Vector3d& innov, double k, double r) {
    const double dr = d_ + r;
    const double sa = k * k * alpha_ + dr;
    const double sb = k * k * beta_ + dr;
    const double inv = 1.0 / (sa * sb);
    ia_ = sb * inv;
    ib_ = sa * inv;
    // u is unit here (renormalised after each correction, rotated by predictions, set unit)
    const double along = u_.dot(innov);
    const double ga = k * alpha_ * ia_;
    const double ea = d_ * ia_;
    const Eigen::Vector3d u_prior = u_;
    u_.noalias() += ga * innov + ((k * beta_ * ib_ - ga) * along) * u_prior;
    e_.noalias() = ea * innov + ((d_ * ib_ - ea) * along) * u_prior;
    alpha_ *= dr * ia_;
    beta_ *= dr * ib_;
    kd_ = -k * d_;
    dr_ = dr;
    layout_ = Layout::kTangentPosterior;
    u_.normalize();
  }

  /// The update of correct() when P = blkdiag(A, d I) and e = 0 (right after a prediction with
  /// c = 0), in closed form with S = k^2 A + (d + r) I: u += k A S^-1 v, e = d S^-1 v,
  /// P11 = A - k^2 A S^-1 A = (d + r) A S^-1 (as S - k^2 A = (d + r) I), P12 = -k d A S^-1,
  /// P22 = d I - d^2 S^-1. A and S^-1 commute, so A S^-1 is symmetric. The same posterior as the
  /// three scalar updates, at about a third of their cost. P12 and P22 are kept as A S^-1 and
  /// S^-1 and written only when covariance() is asked (the next prediction with c = 0 drops them).
  void correct_decoupled(const Eigen::Vector3d& innov, double k, double r) {
    const Eigen::Matrix3d a = p_mat_.topLeftCorner<3, 3>();
    const double d = d_;
    const double dr = d + r;
    Eigen::Matrix3d s = (k * k) * a;
    s.diagonal().array() += dr;
    s_inv_ = symmetric_inverse(s);
    as_.noalias() = a * s_inv_;
    as_ = 0.5 * (as_ + as_.transpose()).eval();
    u_.noalias() += k * (as_ * innov);
    e_.noalias() = d * (s_inv_ * innov);
    p_mat_.topLeftCorner<3, 3>() = dr * as_;
    kd_ = -k * d;
    layout_ = Layout::kDecoupledPosterior;
    if (p_.renormalize) {
      u_.normalize();
    }
  }

  /// Writes the blocks of p_mat_ the layout keeps implicit (P11 too in the tangent form).
  /// Writes P12, P21 and P22 of `p` (P11 already in it) from the layout's kept quantities.
  void fill_blocks(Matrix6& p) const {
    if (tangent()) {
      p.topLeftCorner<3, 3>() = tangent_matrix(alpha_, beta_);
      if (layout_ == Layout::kTangentPosterior) {  // P11_prior S^-1 = P11 / (d + r); S^-1's eigenvalues
        p.topRightCorner<3, 3>() = tangent_matrix(kd_ * alpha_ / dr_, kd_ * beta_ / dr_);
        p.bottomLeftCorner<3, 3>() = p.topRightCorner<3, 3>();
        p.bottomRightCorner<3, 3>() = tangent_matrix(d_ - d_ * d_ * ia_, d_ - d_ * d_ * ib_);
        return;
      }
    }
    if (layout_ == Layout::kBlockDiagonal || layout_ == Layout::kTangentPrior) {
      p.topRightCorner<3, 3>().setZero();
      p.bottomLeftCorner<3, 3>().setZero();
      p.bottomRightCorner<3, 3>().setZero();
      p.bottomRightCorner<3, 3>().diagonal().setConstant(d_);
    } else if (layout_ == Layout::kDecoupledPosterior) {
      p.topRightCorner<3, 3>() = kd_ * as_;
      p.bottomLeftCorner<3, 3>() = p.topRightCorner<3, 3>();
      p.bottomRightCorner<3, 3>() = (-d_ * d_) * s_inv_;
      p.bottomRightCorner<3, 3>().diagonal().array() += d_;
    }
  }
  /// Stores P in full (before an update that needs every block).
  void materialize() {
    fill_blocks(p_mat_);
    layout_ = Layout::kFull;
  }

  DirectionKfParams p_;
  Eigen::Vector3d u_{0.0, 0.0, 1.0};
  Eigen::Vector3d e_{0.0, 0.0, 0.0};
  // How much of P p_mat_ holds: all of it; P11 of blkdiag(P11, d_ I) with e = 0 (a prediction
  // with c = 0, which correct() then updates in closed form); P11 of the closed-form posterior,
  // P12 = kd_ as_, P22 = d_ I - d_^2 s_inv_ (correct_decoupled).
  // kTangentPrior / kTangentPosterior: the same two layouts in the tangent form (notation): P11 =
  // alpha_ (I - u u^T) + beta_ u u^T (p_mat_'s P11 not written); the posterior's P12 = kd_ P11 /
  // dr_, P22 = d_ I - d_^2 S^-1 with S^-1's eigenvalues ia_ across u, ib_ along it.
  enum class Layout : uint8_t { kFull, kBlockDiagonal, kDecoupledPosterior, kTangentPrior, kTangentPosterior };
  Matrix6 p_mat_ = Matrix6::Identity();
  Layout layout_ = Layout::kFull;
  double d_ = 0.0;
  double kd_ = 0.0;
  double alpha_ = 0.0;
  double beta_ = 0.0;
  double ia_ = 0.0;
  double ib_ = 0.0;
  double dr_ = 1.0;
  Eigen::Matrix3d as_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d s_inv_ = Eigen::Matrix3d::Zero();
  mutable double cached_h_ = -1.0;  // step_c() cache (the pow is only recomputed when h changes)
  mutable double cached_c_ = 0.0;
};

}  // namespace poise
