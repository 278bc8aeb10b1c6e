#include "poise/core/attitude.h"
#include "poise/eval/broad.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>

namespace poise::eval {

BroadTrial decimate_trial(const BroadTrial& in, size_t every) {
  if (every == 0 || in.size() < 2 * every) {
    throw std::invalid_argument("decimate: trial '" + in.stem + "' every " + std::to_string(every) +
                                " leaves fewer than 2 samples (or every is 0)");
  }
  BroadTrial out = in;
  out.rate_hz = in.rate_hz / static_cast<double>(every);
  auto keep = [every](auto& rows) {
    size_t j = 0;
    for (size_t k = 0; k < rows.size(); k += every) {
      rows[j++] = rows[k];
    }
    rows.resize(j);
  };
  keep(out.gyr_rps);
  keep(out.acc_mps2);
  keep(out.mag_ut);
  keep(out.opt_quat_wxyz);
  keep(out.movement);
  if (!out.opt_pos_m.empty()) {
    keep(out.opt_pos_m);
  }
  return out;
}

BroadTrial attach_magnet(const BroadTrial& in, const Eigen::Vector3d& offset_ut, double from_s) {
  if (!offset_ut.allFinite() || !std::isfinite(from_s)) {
    throw std::invalid_argument("attach_magnet: trial '" + in.stem + "': the offset and its start must be finite");
  }
  BroadTrial out = in;
  for (size_t k = 0; k < out.mag_ut.size(); ++k) {
    if (static_cast<double>(k) / out.rate_hz >= from_s) {
      out.mag_ut[k] += offset_ut;
    }
  }
  return out;
}

Eigen::Vector3d attached_magnet_offset(int number, double magnitude_ut) {
  std::mt19937_64 rng(static_cast<uint64_t>(number) + 0x9e3779b97f4a7c15ULL);
  // the engine's numbers are fixed by the standard, a distribution's are not: [0, 1) from the top 53 bits
  auto unit = [&rng] { return static_cast<double>(rng() >> 11) * 0x1.0p-53; };
  const double z = 2.0 * unit() - 1.0;  // uniform on the sphere: z uniform in [-1, 1], azimuth uniform
  const double az = 2.0 * kPi * unit();
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  return magnitude_ut * Eigen::Vector3d(r * std::cos(az), r * std::sin(az), z);
}

BroadTrial resample_trial(const BroadTrial& in, double rate_hz) {
  try {
    check_rate(rate_hz, "resample: rate");
  } catch (const std::runtime_error& e) {
    throw std::invalid_argument(e.what());
  }
  const size_t n = in.size();
  if (n < 2 || !(in.rate_hz > 0.0)) {
    throw std::invalid_argument("resample: trial '" + in.stem + "' has fewer than 2 samples or no rate");
  }
  const double dt_in = 1.0 / in.rate_hz;
  // Orientation of the body relative to its start, from the gyro at the original rate.
  std::vector<Eigen::Quaterniond> q_gyro;
  q_gyro.reserve(n);
  q_gyro.push_back(Eigen::Quaterniond::Identity());
  for (size_t k = 1; k < n; ++k) {
    q_gyro.push_back(quat_integrate_body_rate(q_gyro.back(), in.gyr_rps[k], dt_in));
  }
  const double duration_s = static_cast<double>(n - 1) * dt_in;
  const auto m = static_cast<size_t>(std::floor(duration_s * rate_hz + 1e-9)) + 1;
  BroadTrial out;
  out.path = in.path;
  out.stem = in.stem;
  out.number = in.number;
  out.rate_hz = rate_hz;
  out.gyr_rps.reserve(m);
  out.acc_mps2.reserve(m);
  out.mag_ut.reserve(m);
  out.opt_quat_wxyz.reserve(m);
  out.movement.reserve(m);
  out.opt_pos_m.reserve(in.opt_pos_m.empty() ? 0 : m);
  const double nan = std::nan("");
  Eigen::Quaterniond q_prev = Eigen::Quaterniond::Identity();
  for (size_t j = 0; j < m; ++j) {
    const double t = static_cast<double>(j) / rate_hz;
    const double x = std::min(t * in.rate_hz, static_cast<double>(n - 1));
    const auto k = std::min(static_cast<size_t>(x), n - 2);
    const double f = x - static_cast<double>(k);
    const Eigen::Quaterniond q = q_gyro[k].slerp(f, q_gyro[k + 1]);
    out.gyr_rps.push_back(j == 0 ? in.gyr_rps[0] : Eigen::Vector3d(quat_log(q_prev.conjugate() * q) * rate_hz));
    q_prev = q;
    out.acc_mps2.push_back((1.0 - f) * in.acc_mps2[k] + f * in.acc_mps2[k + 1]);
    out.mag_ut.push_back((1.0 - f) * in.mag_ut[k] + f * in.mag_ut[k + 1]);
    const Eigen::Vector4d& r0 = in.opt_quat_wxyz[k];
    const Eigen::Vector4d& r1 = in.opt_quat_wxyz[k + 1];
    if (r0.allFinite() && r1.allFinite() && r0.norm() > 0.0 && r1.norm() > 0.0) {
      const Eigen::Quaterniond a = quat_from_wxyz(r0).normalized();
      const Eigen::Quaterniond b = quat_from_wxyz(r1).normalized();
      out.opt_quat_wxyz.push_back(quat_to_wxyz_vec(a.slerp(f, b)));
    } else {
      out.opt_quat_wxyz.push_back(Eigen::Vector4d::Constant(nan));
    }
    out.movement.push_back(in.movement[f < 0.5 ? k : k + 1]);
    if (!in.opt_pos_m.empty()) {
      out.opt_pos_m.push_back((1.0 - f) * in.opt_pos_m[k] + f * in.opt_pos_m[k + 1]);
    }
  }
  return out;
}

}  // namespace poise::eval
