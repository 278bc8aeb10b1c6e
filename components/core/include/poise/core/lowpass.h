// Low-pass filters with time constants in seconds, for any sample rate (the coefficients follow
// the actual step). Pure math, no state beyond the filter's own.
#pragma once

#include <Eigen/Core>

#include <algorithm>
#include <cmath>

namespace poise {

/// Second-order Butterworth low-pass of a fixed-size vector, parametrised by a time constant tau
/// (s): cut-off f_c = sqrt(2) / (2 pi tau), so a ramp is followed with a lag of tau seconds (the
/// same lag as a first-order filter with time constant tau, with -40 dB/decade above f_c instead of
/// -20). Discretised by the bilinear transform with pre-warping; the coefficients are recomputed
/// when the step changes by more than 0.1 %. The first sample initialises the filter at rest on it.
template <int N>
class Butterworth2 {
 public:
  using Vec = Eigen::Matrix<double, N, 1>;

  explicit Butterworth2(double tau_s = 1.0) : tau_s_(tau_s) {}

  void set_tau(double tau_s) {
    tau_s_ = tau_s;
    cached_dt_s_ = -1.0;
  }
  [[nodiscard]] double tau_s() const { return tau_s_; }
  void reset() { initialized_ = false; }
  [[nodiscard]] bool initialized() const { return initialized_; }

  /// Starts at rest on x (output x).
  void reset(const Vec& x) {
    y_ = x;
    initialized_ = true;
    steady_ = true;
  }

  /// Filters one sample taken dt_s after the previous one; returns the output.
  const Vec& step(const Vec& x, double dt_s) {
    if (!initialized_) {
      reset(x);
      return y_;
    }
    coefficients(dt_s);
    if (steady_) {  // the state that makes the filter rest on y_
      s1_ = (b1_ - a1_ + b2_ - a2_) * y_;
      s2_ = (b2_ - a2_) * y_;
      steady_ = false;
    }
    // direct form II transposed
    y_ = b0_ * x + s1_;
    s1_ = b1_ * x - a1_ * y_ + s2_;
    s2_ = b2_ * x - a2_ * y_;
    return y_;
  }

  [[nodiscard]] const Vec& output() const { return y_; }

  /// Replaces the state by a rest on x (e.g. after the frame of the filtered quantity changed).
  void rest_on(const Vec& x) { reset(x); }
  /// Applies the linear map m (N x N) to the whole state: afterwards the filter is as if it had
  /// been fed m x instead of every past x (e.g. the frame of the filtered quantity turned by m).
  template <typename Map>
  void transform(const Map& m) {
    y_ = m * y_;
    s1_ = m * s1_;
    s2_ = m * s2_;
  }

 private:
  void coefficients(double dt_s) {
    if (cached_dt_s_ > 0.0 && std::abs(dt_s - cached_dt_s_) <= 1e-3 * cached_dt_s_) {
      return;
    }
    cached_dt_s_ = dt_s;
    constexpr double kSqrt2 = 1.41421356237309504880;
    constexpr double kPiLocal = 3.14159265358979323846;
    const double fc_hz = kSqrt2 / (2.0 * kPiLocal * tau_s_);
    // Nyquist guard: a time constant shorter than the step degenerates to a pass-through.
    const double wt = std::min(kPiLocal * fc_hz * dt_s, 0.49 * kPiLocal);
    const double k = std::tan(wt);
    const double norm = 1.0 / (1.0 + kSqrt2 * k + k * k);
    b0_ = k * k * norm;
    b1_ = 2.0 * b0_;
    b2_ = b0_;
    a1_ = 2.0 * (k * k - 1.0) * norm;
    a2_ = (1.0 - kSqrt2 * k + k * k) * norm;
  }

  double tau_s_;
  double cached_dt_s_ = -1.0;
  double b0_ = 1.0, b1_ = 0.0, b2_ = 0.0, a1_ = 0.0, a2_ = 0.0;
  Vec y_ = Vec::Zero();
  Vec s1_ = Vec::Zero();
  Vec s2_ = Vec::Zero();
  bool initialized_ = false;
  bool steady_ = true;
};

/// First-order low-pass y += dt / (tau + dt) (x - y) with tau in seconds; the first sample
/// initialises it.
template <int N>
class FirstOrderLowPass {
 public:
  using Vec = Eigen::Matrix<double, N, 1>;
  explicit FirstOrderLowPass(double tau_s = 1.0) : tau_s_(tau_s) {}
  void reset() { initialized_ = false; }
  const Vec& step(const Vec& x, double dt_s) {
    if (!initialized_) {
      y_ = x;
      initialized_ = true;
    } else {
      y_ += (dt_s / (tau_s_ + dt_s)) * (x - y_);
    }
    return y_;
  }
  [[nodiscard]] const Vec& output() const { return y_; }
  [[nodiscard]] bool initialized() const { return initialized_; }

 private:
  double tau_s_;
  Vec y_ = Vec::Zero();
  bool initialized_ = false;
};

}  // namespace poise
