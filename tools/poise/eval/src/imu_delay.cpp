#include "poise/eval/imu_delay.h"

#include "poise/core/attitude.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>

namespace poise::eval {
namespace {

Eigen::Quaterniond quat(const Eigen::Vector4d& v) {
  return Eigen::Quaterniond(v[0], v[1], v[2], v[3]).normalized();
}

/// Reference at fractional index k (slerp between neighbours).
Eigen::Quaterniond ref_at(const std::vector<Eigen::Vector4d>& ref, double k) {
  const auto i = static_cast<size_t>(std::floor(k));
  const double f = k - static_cast<double>(i);
  return quat(ref[i]).slerp(f, quat(ref[i + 1]));
}

}  // namespace

ImuDelayEstimate estimate_imu_delay(const std::vector<Eigen::Vector3d>& gyro_rps,
                                    const std::vector<Eigen::Vector4d>& q_ref_wxyz,
                                    const std::vector<uint8_t>& use, const ImuDelayOptions& o) {
  ImuDelayEstimate est;
  const size_t n = std::min(gyro_rps.size(), q_ref_wxyz.size());
  if (!(o.rate_hz > 0.0) || o.window_samples < 2 || o.stride < 1 || !(o.step_samples > 0.0)) {
    est.why = "invalid options";
    return est;
  }
  const int margin = static_cast<int>(std::ceil(o.max_lag_samples)) + 1;
  const double h = 1.0 / o.rate_hz;
  // Windows: start k, the gyro rotation over [k, k + W] (trapezoidal: the rate sampled at both
  // ends of each interval, so the estimate carries no half-sample bias), valid reference
  // over the whole searched span, enough rotation to carry timing information.
  std::vector<size_t> starts;
  std::vector<Eigen::Quaterniond> rotation;
  for (size_t k = static_cast<size_t>(margin); k + o.window_samples + margin + 1 < n; k += o.stride) {
    if (!use.empty() && use[k] == 0) {
      continue;
    }
    bool valid = true;
    double rate = 0.0;
    for (int j = -margin; j <= o.window_samples + margin && valid; ++j) {
      valid = q_ref_wxyz[k + j].allFinite();
    }
    if (!valid) {
      continue;
    }
    Eigen::Quaterniond r = Eigen::Quaterniond::Identity();
    for (int j = 0; j < o.window_samples; ++j) {
      if (!gyro_rps[k + j].allFinite() || !gyro_rps[k + j + 1].allFinite()) {
        valid = false;
        break;
      }
      rate += gyro_rps[k + j].norm();
      r = r * quat_exp(0.5 * (gyro_rps[k + j] + gyro_rps[k + j + 1]) * h);
    }
    if (!valid || rate / o.window_samples < o.min_rate_rps) {
      continue;
    }
    starts.push_back(k);
    rotation.push_back(r.normalized());
  }
  est.windows = starts.size();
  if (starts.size() < 20) {
    est.why = "fewer than 20 windows with motion and a valid reference";
    return est;
  }
  // RMS window-end error when the gyro at index k describes the reference at index k - lag.
  auto rms_deg = [&](double lag) {
    double sum = 0.0;
    for (size_t w = 0; w < starts.size(); ++w) {
      const double k0 = static_cast<double>(starts[w]) - lag;
      const Eigen::Quaterniond predicted = ref_at(q_ref_wxyz, k0) * rotation[w];
      const Eigen::Quaterniond actual = ref_at(q_ref_wxyz, k0 + o.window_samples);
      const double e = quat_angle_between(predicted, actual);
      sum += e * e;
    }
    return std::sqrt(sum / static_cast<double>(starts.size())) * kDegPerRad;
  };
  const int steps = static_cast<int>(std::llround(o.max_lag_samples / o.step_samples));
  std::vector<double> curve;
  int best = 0;
  for (int i = -steps; i <= steps; ++i) {
    curve.push_back(rms_deg(i * o.step_samples));
    if (curve.back() < curve[static_cast<size_t>(best)]) {
      best = static_cast<int>(curve.size()) - 1;
    }
  }
  est.rms_at_zero_deg = curve[static_cast<size_t>(steps)];
  if (best == 0 || best == static_cast<int>(curve.size()) - 1) {
    est.why = "minimum on the edge of the searched lags";
    return est;
  }
  // Parabola through the best grid point and its neighbours.
  const double a = curve[static_cast<size_t>(best) - 1];
  const double b = curve[static_cast<size_t>(best)];
  const double c = curve[static_cast<size_t>(best) + 1];
  const double denom = a - 2.0 * b + c;
  const double offset = denom > 0.0 ? 0.5 * (a - c) / denom : 0.0;
  est.delay_samples = (best - steps + offset) * o.step_samples;
  est.delay_s = est.delay_samples * h;
  est.rms_at_delay_deg = rms_deg(est.delay_samples);
  est.ok = true;
  return est;
}

}  // namespace poise::eval
