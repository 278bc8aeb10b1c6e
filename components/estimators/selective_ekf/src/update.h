// Private to the selective EKF (src/): the measurement update every aid source uses, and the
// status bookkeeping of a decision. Notation: selective_ekf.h.
#pragma once

#include "poise/selective_ekf/selective_ekf.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace poise::selective_ekf_aids {

constexpr double kNsToS = 1e-9;
/// Gate used only to report a test ratio for sources that are never gated (gyro, q_imu), sigma.
constexpr double kReportGateSigma = 5.0;

inline int64_t seconds_to_ns(double s) { return static_cast<int64_t>(std::llround(s * 1e9)); }

/// A quaternion the filter can normalise: finite, norm within [0.5, 1.5].
inline bool finite_quat(const Eigen::Quaterniond& q) {
  return q.coeffs().allFinite() && q.coeffs().norm() > 0.5 && q.coeffs().norm() < 1.5;
}

/// Whether every row of `h` selects states: entries 0 or 1, at most two 1s a row (the gyro's, the
/// rest aid's rows). A product with such rows has at most two non-zero terms in each sum, whose
/// value no order of summation changes: times_ht() then gives a dense product's numbers by
/// selection, bit for bit, at a fraction of its cost.
template <int M, int N>
bool selector_rows(const Eigen::Matrix<double, M, N>& h) {
  for (int i = 0; i < M; ++i) {
    int ones = 0;
    for (int j = 0; j < N; ++j) {
      if (h(i, j) == 1.0) {
        ++ones;
      } else if (h(i, j) != 0.0) {
        return false;
      }
    }
    if (ones > 2) {
      return false;
    }
  }
  return true;
}

/// C H^T, with `selector` = selector_rows(h): by selection (column i the sum of the columns of C
/// row i picks), else C.lazyProduct(H^T).
template <typename CMat, int M, int N>
Eigen::Matrix<double, CMat::RowsAtCompileTime, M> times_ht(const CMat& c, const Eigen::Matrix<double, M, N>& h,
                                                           bool selector) {
  Eigen::Matrix<double, CMat::RowsAtCompileTime, M> out;
  if (!selector) {
    out.noalias() = c.lazyProduct(h.transpose());
    return out;
  }
  out.setZero();
  for (int i = 0; i < M; ++i) {
    for (int j = 0; j < N; ++j) {
      if (h(i, j) == 1.0) {
        out.col(i) += c.col(j);
      }
    }
  }
  return out;
}

/// H A, with `selector` = selector_rows(h): by selection (row i the sum of the rows of A row i of
/// H picks), else H.lazyProduct(A).
template <int M, int N, typename AMat>
Eigen::Matrix<double, M, AMat::ColsAtCompileTime> h_times(const Eigen::Matrix<double, M, N>& h, const AMat& a,
                                                          bool selector) {
  Eigen::Matrix<double, M, AMat::ColsAtCompileTime> out;
  if (!selector) {
    out.noalias() = h.lazyProduct(a);
    return out;
  }
  out.setZero();
  for (int i = 0; i < M; ++i) {
    for (int j = 0; j < N; ++j) {
      if (h(i, j) == 1.0) {
        out.row(i) += a.row(j);
      }
    }
  }
  return out;
}

/// Update with M rows of a dense H (M x N) and diagonal R, processed one row at a time (exact for
/// a diagonal R: the same result as the batch update, at O(M N^2) instead of O(M N^3)):
///   v_i = P h_i^T (prior), u_i = v_i - sum_{j<i} u_j (h_i . u_j) / s_j (= P_{i-1} h_i^T),
///   s_i = h_i . u_i + r_i, dx += u_i (y_i - h_i . dx) / s_i, P -= u_i u_i^T / s_i.
/// P - K S K^T equals the Joseph form for this (optimal) gain; each rank-one term is symmetric.
/// The status gets the innovation, the prior innovation variance diag(H P H^T + R) and the test
/// ratio; the gate tests the prior variance. Leaves `p` and `dx` untouched when the gate rejects
/// or `report_only`. Returns whether the rows were applied.
template <int N, int M, typename PMat>
bool sequential_update(PMat&& p, const Eigen::Matrix<double, M, N>& h,
                       const Eigen::Matrix<double, M, 1>& innov,
                       const Eigen::Matrix<double, M, 1>& r_diag, double gate_sigma, bool gate,
                       bool report_only, SourceStatus& st, Eigen::Matrix<double, N, 1>& dx) {
  const bool selector = selector_rows(h);
  Eigen::Matrix<double, N, M> u = times_ht(p, h, selector);  // prior P H^T
  double ratio = 0.0;
  st.innovation.setZero();
  st.innovation_variance.setZero();
  for (int i = 0; i < M; ++i) {
    const double s_prior = h.row(i).dot(u.col(i)) + r_diag[i];
    st.innovation[i] = innov[i];
    st.innovation_variance[i] = s_prior;
    ratio = std::max(ratio, innov[i] * innov[i] / (gate_sigma * gate_sigma * s_prior));
  }
  st.test_ratio = ratio;
  if (report_only || (gate && !(ratio <= 1.0))) {
    return false;
  }
  dx.setZero();
  Eigen::Matrix<double, M, 1> s;
  for (int i = 0; i < M; ++i) {
    for (int j = 0; j < i; ++j) {
      u.col(i) -= u.col(j) * (h.row(i).dot(u.col(j)) / s[j]);
    }
    s[i] = h.row(i).dot(u.col(i)) + r_diag[i];
    dx += u.col(i) * ((innov[i] - h.row(i).dot(dx)) / s[i]);  // (5), (6)
  }
  for (int i = 0; i < M; ++i) {
    const Eigen::Matrix<double, N, 1> w = u.col(i) / std::sqrt(s[i]);
    p.noalias() -= w * w.transpose();  // (7), exactly symmetric
  }
  return true;
}

/// sequential_update on the diagonal block [Off, Off + NB) of P alone (the caller knows that H
/// and P's cross terms outside it are zero); dx gets the block's correction.
template <int Off, int NB, int N, int M>
bool update_block(Eigen::Matrix<double, N, N>& p, const Eigen::Matrix<double, M, N>& h,
                  const Eigen::Matrix<double, M, 1>& innov, const Eigen::Matrix<double, M, 1>& r_diag,
                  double gate_sigma, bool gate, bool report_only, SourceStatus& st,
                  Eigen::Matrix<double, N, 1>& dx) {
  Eigen::Matrix<double, NB, 1> d;
  const Eigen::Matrix<double, M, NB> hb = h.template middleCols<NB>(Off);
  const bool ok = sequential_update<NB, M>(p.template block<NB, NB>(Off, Off), hb, innov, r_diag,
                                           gate_sigma, gate, report_only, st, d);
  if (ok) {
    dx.template segment<NB>(Off) = d;
  }
  return ok;
}

/// Adds an error-state correction to the nominal state (attitude on the right: q <- q exp(dth)).
inline void inject(SelectiveEkfState& x, const SelectiveEkf::Vec& dx) {
  x.w_rps += dx.segment<3>(SelectiveEkf::kW);
  x.q_world_body = (x.q_world_body * quat_exp(dx.segment<3>(SelectiveEkf::kTh))).normalized();
  x.b_rps += dx.segment<3>(SelectiveEkf::kB);
  // The accelerometer low-pass's error e (its up vector turned by exp(-e) against the truth,
  // aid_accel_tilt.cpp): its correction turns the low-pass by -de.
  const Eigen::Vector3d turn = -dx.segment<3>(SelectiveEkf::kE);
  if (turn.squaredNorm() > 0.0) {
    x.pre.lp_accel_i = quat_exp(turn) * x.pre.lp_accel_i;
  }
  x.t_m += dx.segment<3>(SelectiveEkf::kT);
  x.v_mps += dx.segment<3>(SelectiveEkf::kV);
}

/// The estimate's error covariance (SelectiveEkfState::P_err), and the external acceleration's
/// error ext_accel_error, after rows H with the gain K (from P) and diagonal R: the Joseph form, exact for any gain, (I - K H) C (I - K H)^T + K R K^T =
/// C - K A^T - A K^T + K S K^T with A = C H^T, S = H A + R (symmetric) = C + G K^T + K G^T with
/// G = K S / 2 - A: one N x M x N product, and symmetric to the bit by construction (m_ij + m_ji).
/// On the diagonal block [Off, Off + NB) alone when the caller knows that K, H and C's cross terms
/// outside it are zero (the attitude block's rows while x.coupled is false: the same numbers at
/// (12 / 18)^2 of the cost).
template <int Off, int NB, int M>
void update_error_covariance_block(SelectiveEkfState& x, const Eigen::Matrix<double, SelectiveEkf::kN, M>& k_full,
                                   const Eigen::Matrix<double, M, SelectiveEkf::kN>& h_full,
                                   const Eigen::Matrix<double, M, 1>& r_diag) {
  auto c = x.P_err.template block<NB, NB>(Off, Off);
  const Eigen::Matrix<double, NB, M> k = k_full.template middleRows<NB>(Off);
  const Eigen::Matrix<double, M, NB> h = h_full.template middleCols<NB>(Off);
  // the external acceleration's error (SelectiveEkfState::ext_accel_error): the same gain, z <- (I - K H) z
  auto z = x.ext_accel_error.template segment<NB>(Off);
  const Eigen::Matrix<double, M, 1> hz = h * z;
  z -= k * hz;
  // the heading error an offset left in the readings put in (SelectiveEkfState::heading_per_offset):
  // these rows take back their share of a world heading error, u^T K H u (u: up in the body)
  if constexpr (Off == 0 && NB >= SelectiveEkf::kTh + 3) {
    if (!x.heading_per_offset.isZero() || !x.heading_per_removed_offset.isZero() || x.offset_left_var > 0.0) {
      const Eigen::Vector3d u = x.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
      const Eigen::Matrix<double, M, 1> hu = h.template middleCols<3>(SelectiveEkf::kTh) * u;
      const double kept = 1.0 - u.dot(k.template middleRows<3>(SelectiveEkf::kTh) * hu);
      x.heading_per_offset *= kept;
      x.heading_per_removed_offset *= kept;
      x.offset_left_var *= kept * kept;
    }
  }
  const bool selector = selector_rows(h);
  const Eigen::Matrix<double, NB, M> a = times_ht(c, h, selector);
  Eigen::Matrix<double, M, M> s = h_times(h, a, selector);
  s.diagonal() += r_diag;
  const Eigen::Matrix<double, NB, M> g = 0.5 * k.lazyProduct(s) - a;
  Eigen::Matrix<double, NB, NB> m;
  m.noalias() = g.lazyProduct(k.transpose());
  c += m + m.transpose();
}

/// update_error_covariance_block over the whole error state, or on the attitude block alone when
/// `att_only` (rows and gain there only, no cross-covariance: x.coupled false).
template <int M>
void update_error_covariance(SelectiveEkfState& x, const Eigen::Matrix<double, SelectiveEkf::kN, M>& k,
                             const Eigen::Matrix<double, M, SelectiveEkf::kN>& h,
                             const Eigen::Matrix<double, M, 1>& r_diag, bool att_only) {
  if (att_only) {
    update_error_covariance_block<0, SelectiveEkf::kAttN, M>(x, k, h, r_diag);
  } else {
    update_error_covariance_block<0, SelectiveEkf::kN, M>(x, k, h, r_diag);
  }
}

/// Whether rows H touch the attitude block [w, th, b, e] alone while it has no cross-covariance
/// with [t, v] (x.coupled false): their gain is zero outside it.
template <int M>
bool attitude_rows_only(const SelectiveEkfState& x, const Eigen::Matrix<double, M, SelectiveEkf::kN>& h) {
  return !x.coupled && !(h.template rightCols<SelectiveEkf::kN - SelectiveEkf::kAttN>().array() != 0.0).any();
}

/// The fuse step of every aid: M rows with a dense H (M x kN) and diagonal R, one row at a time;
/// runs on the [w, th, b] or [t, v] block alone while they are uncorrelated (x.coupled false).
/// Fills the status's innovation, variance and test ratio; false when the gate rejects (or
/// `report_only`: the innovation of rows left out). `r_err_diag`: the rows' real white noise,
/// what the estimate's error covariance P_err counts (the sensor's figure where it differs from
/// the design's r_diag, which sets the gain).
template <int M>
bool fuse(SelectiveEkfState& x, const Eigen::Matrix<double, M, SelectiveEkf::kN>& h,
          const Eigen::Matrix<double, M, 1>& innov, const Eigen::Matrix<double, M, 1>& r_diag,
          const Eigen::Matrix<double, M, 1>& r_err_diag, double gate_sigma, bool gate, SourceStatus& st,
          bool report_only = false) {
  constexpr int kN = SelectiveEkf::kN;
  constexpr int kAttN = SelectiveEkf::kAttN;
  const bool att = (h.template leftCols<kAttN>().array() != 0.0).any();
  const bool trans = (h.template rightCols<kN - kAttN>().array() != 0.0).any();
  SelectiveEkf::Vec dx = SelectiveEkf::Vec::Zero();
  const bool att_only = att && !trans && !x.coupled;  // (before a lever-arm fix couples them)
  // P's (optimal) gain before these rows, for the estimate's error covariance: K = P H^T S^-1
  // (on the attitude block alone for its rows while uncoupled: zero elsewhere)
  Eigen::Matrix<double, kN, M> k = Eigen::Matrix<double, kN, M>::Zero();
  if (att_only) {
    const Eigen::Matrix<double, M, kAttN> ha = h.template leftCols<kAttN>();
    const bool selector = selector_rows(ha);
    const Eigen::Matrix<double, kAttN, M> u = times_ht(x.P.template topLeftCorner<kAttN, kAttN>(), ha, selector);
    Eigen::Matrix<double, M, M> s = h_times(ha, u, selector);
    s.diagonal() += r_diag;
    k.template topRows<kAttN>() = u * s.inverse();
  } else {
    const Eigen::Matrix<double, kN, M> u = x.P * h.transpose();
    Eigen::Matrix<double, M, M> s = h * u;
    s.diagonal() += r_diag;
    k = u * s.inverse();
  }
  bool ok = false;
  if (!x.coupled && !(att && trans)) {
    // No cross-covariance between [w, th, b] and [t, v]: rows touching one block update it alone
    // (the rest of K is exactly zero), with the same result as the full covariance.
    ok = att ? update_block<0, kAttN>(x.P, h, innov, r_diag, gate_sigma, gate, report_only, st, dx)
             : update_block<kAttN, kN - kAttN>(x.P, h, innov, r_diag, gate_sigma, gate, report_only,
                                               st, dx);
  } else {
    x.coupled = x.coupled || !report_only;  // a lever-arm fix correlates attitude and position
    ok = sequential_update<kN, M>(x.P, h, innov, r_diag, gate_sigma, gate, report_only, st, dx);
  }
  if (ok) {
    update_error_covariance<M>(x, k, h, r_err_diag, att_only);
    inject(x, dx);
  }
  return ok;
}

/// fuse() of rows whose real noise is their design noise (P_err counts r_diag).
template <int M>
bool fuse(SelectiveEkfState& x, const Eigen::Matrix<double, M, SelectiveEkf::kN>& h,
          const Eigen::Matrix<double, M, 1>& innov, const Eigen::Matrix<double, M, 1>& r_diag,
          double gate_sigma, bool gate, SourceStatus& st, bool report_only = false) {
  return fuse<M>(x, h, innov, r_diag, r_diag, gate_sigma, gate, st, report_only);
}

/// M rows with the gain K = P H^T S^-1 projected by `keep` (kN x kN; a Schmidt consider update:
/// what `keep` removes keeps its uncertainty and its correlations and learns nothing from these
/// rows), P <- (I - K H) P (I - K H)^T + K R K^T (the Joseph form, exact for any gain); P_err the
/// same with the rows' real noise r_err_diag (fuse()). Returns the innovation variances diag(S).
template <int M>
Eigen::Matrix<double, M, 1> fuse_considered(SelectiveEkfState& x, const Eigen::Matrix<double, M, SelectiveEkf::kN>& h,
                                            const Eigen::Matrix<double, M, 1>& innov,
                                            const Eigen::Matrix<double, M, 1>& r_diag,
                                            const Eigen::Matrix<double, M, 1>& r_err_diag, const SelectiveEkf::Mat& keep) {
  const bool att_only = attitude_rows_only<M>(x, h);
  const Eigen::Matrix<double, M, M> r = r_diag.asDiagonal();
  const Eigen::Matrix<double, M, M> s = h * x.P * h.transpose() + r;
  const Eigen::Matrix<double, SelectiveEkf::kN, M> k = keep * (x.P * h.transpose() * s.inverse());
  if (att_only) {
    // (the attitude block alone: K, H and P's cross terms are zero outside it)
    constexpr int kA = SelectiveEkf::kAttN;
    const Eigen::Matrix<double, kA, M> ka = k.template topRows<kA>();
    const Eigen::Matrix<double, kA, kA> ikh =
        Eigen::Matrix<double, kA, kA>::Identity() - ka * h.template leftCols<kA>();
    const Eigen::Matrix<double, kA, kA> updated =
        ikh * x.P.template topLeftCorner<kA, kA>() * ikh.transpose() + ka * r * ka.transpose();
    x.P.template topLeftCorner<kA, kA>() = 0.5 * (updated + updated.transpose());
  } else {
    const SelectiveEkf::Mat ikh = SelectiveEkf::Mat::Identity() - k * h;
    const SelectiveEkf::Mat updated = ikh * x.P * ikh.transpose() + k * r * k.transpose();
    x.P = 0.5 * (updated + updated.transpose());
  }
  update_error_covariance<M>(x, k, h, r_err_diag, att_only);
  inject(x, k * innov);
  return s.diagonal();
}

/// fuse_considered with the bias rows of the gain zeroed (the bias considered).
template <int M>
Eigen::Matrix<double, M, 1> fuse_bias_considered(SelectiveEkfState& x, const Eigen::Matrix<double, M, SelectiveEkf::kN>& h,
                                                 const Eigen::Matrix<double, M, 1>& innov,
                                                 const Eigen::Matrix<double, M, 1>& r_diag,
                                                 const Eigen::Matrix<double, M, 1>& r_err_diag) {
  SelectiveEkf::Mat keep = SelectiveEkf::Mat::Identity();
  keep.block<3, 3>(SelectiveEkf::kB, SelectiveEkf::kB).setZero();
  return fuse_considered<M>(x, h, innov, r_diag, r_err_diag, keep);
}

// ---- The figures the estimate's error covariance P_err uses: the sensor's own where the
// parameters give them (gyro_noise_density_rps_per_sqrt_hz, accel_noise_density_mps2_per_sqrt_hz,
// gyro_bias_walk_rps_per_sqrt_s), else the design's, as the gains (docs/SELECTIVE_EKF.md "The
// sensor's own figures").

/// The gyro row's white noise over a sample interval dt_s, (rad/s)^2: N^2 / dt (a sample is the
/// rate's mean over its interval), else sigma_gyro_rps^2.
inline double err_gyro_variance(const SelectiveEkfParams& p, double dt_s) {
  const double n = p.gyro_noise_density_rps_per_sqrt_hz;
  return std::isnan(n) || !(dt_s > 0.0) ? p.sigma_gyro_rps * p.sigma_gyro_rps : n * n / dt_s;
}
/// The attitude's own process noise density in P_err, rad^2/s: none when the gyro's noise is
/// known (P_err's rate model has no residual: the gyro's white noise reaches the attitude through
/// the gyro row), else the design's sigma_attitude_walk^2.
inline double err_attitude_walk2(const SelectiveEkfParams& p) {
  return std::isnan(p.gyro_noise_density_rps_per_sqrt_hz) ? p.sigma_attitude_walk * p.sigma_attitude_walk : 0.0;
}
/// The bias random walk's density in P_err, (rad/s)^2/s: the gyro's own, else sigma_bias_walk^2.
inline double err_bias_walk2(const SelectiveEkfParams& p) {
  const double w = std::isnan(p.gyro_bias_walk_rps_per_sqrt_s) ? p.sigma_bias_walk : p.gyro_bias_walk_rps_per_sqrt_s;
  return w * w;
}
/// Whether the accelerometer's noise density is known: P_err then carries the low-pass's own
/// noise in e and the tilt rows have no white noise.
inline bool accel_noise_known(const SelectiveEkfParams& p) { return !std::isnan(p.accel_noise_density_mps2_per_sqrt_hz); }

/// The status step of every aid: the decision on a measurement stamped `stamp_ns`. Counters count
/// first passes only (not the replays after a late vision measurement).
inline void record(SourceStatus& st, Decision d, int64_t stamp_ns, bool first_pass) {
  st.last = d;
  st.last_stamp_ns = stamp_ns;
  const bool fused = d == Decision::kFused || d == Decision::kFusedInflated || d == Decision::kReset;
  if (fused) {
    st.last_fused_stamp_ns = stamp_ns;
  }
  if (first_pass) {
    ++st.by_decision[static_cast<size_t>(d)];
    if (fused) {
      ++st.fused;
    } else {
      ++st.rejected;
    }
  }
}

}  // namespace poise::selective_ekf_aids
