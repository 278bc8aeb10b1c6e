#include "poise/imu/calibration.h"

#include <Eigen/LU>
#include <Eigen/SVD>

#include <cmath>
#include <sstream>

namespace poise::imu {
namespace {
constexpr double kMinScale = 0.5;
constexpr double kMaxScale = 2.0;
constexpr double kMaxSoftIronCondition = 10.0;

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t");
  const auto e = s.find_last_not_of(" \t");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}
}  // namespace

bool AxisMap::parse(const std::string& text, AxisMap* out, std::string* error) {
  AxisMap m;
  std::array<bool, 3> used{false, false, false};
  std::stringstream ss(text);
  std::string item;
  int n = 0;
  while (std::getline(ss, item, ',')) {
    item = trim(item);
    if (n >= 3) {
      *error = "axis map '" + text + "' has more than 3 entries";
      return false;
    }
    int sign = 1;
    if (!item.empty() && (item[0] == '+' || item[0] == '-')) {
      sign = item[0] == '-' ? -1 : 1;
      item = item.substr(1);
    }
    if (item.size() != 1 || item[0] < 'x' || item[0] > 'z') {
      *error = "axis map '" + text + "': entry '" + item + "' is not x, y or z (with optional sign)";
      return false;
    }
    const int idx = item[0] - 'x';
    if (used[static_cast<std::size_t>(idx)]) {
      *error = "axis map '" + text + "' uses axis " + item + " twice";
      return false;
    }
    used[static_cast<std::size_t>(idx)] = true;
    m.index[static_cast<std::size_t>(n)] = idx;
    m.sign[static_cast<std::size_t>(n)] = sign;
    ++n;
  }
  if (n != 3) {
    *error = "axis map '" + text + "' must have 3 entries like \"+x,+y,+z\"";
    return false;
  }
  if (m.matrix().determinant() < 0) {
    *error = "axis map '" + text +
             "' is left-handed (det -1): flip the sign of one axis to keep a right-handed body frame";
    return false;
  }
  *out = m;
  return true;
}

std::string AxisMap::to_string() const {
  std::string s;
  for (std::size_t i = 0; i < 3; ++i) {
    if (i > 0) s += ',';
    s += sign[i] < 0 ? '-' : '+';
    s += static_cast<char>('x' + index[i]);
  }
  return s;
}

Eigen::Matrix3d AxisMap::matrix() const {
  Eigen::Matrix3d r = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < 3; ++i) {
    r(static_cast<Eigen::Index>(i), index[i]) = sign[i];
  }
  return r;
}

std::string Calibration::validate() const {
  const auto finite = [](const auto& m) { return m.allFinite(); };
  if (!finite(gyro_bias_rps) || !finite(accel_bias_mps2) || !finite(mag_hard_iron_ut) ||
      !finite(gyro_scale) || !finite(accel_scale) || !finite(mag_soft_iron)) {
    return "calibration values must be finite numbers";
  }
  const auto scale_ok = [](const Eigen::Vector3d& s) {
    return s.minCoeff() >= kMinScale && s.maxCoeff() <= kMaxScale;
  };
  if (!scale_ok(gyro_scale)) return "gyro_scale entries must be in [0.5, 2]";
  if (!scale_ok(accel_scale)) return "accel_scale entries must be in [0.5, 2]";
  if (gyro_bias_rps.cwiseAbs().maxCoeff() > 1.0) return "gyro_bias_rps entries must be within +-1 rad/s";
  if (accel_bias_mps2.cwiseAbs().maxCoeff() > 5.0) {
    return "accel_bias_mps2 entries must be within +-5 m/s^2";
  }
  if (mag_hard_iron_ut.cwiseAbs().maxCoeff() > 1000.0) {
    return "mag_hard_iron_ut entries must be within +-1000 uT";
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(mag_soft_iron);
  const Eigen::Vector3d sv = svd.singularValues();
  if (sv(2) <= 1e-9 || sv(0) / sv(2) > kMaxSoftIronCondition) {
    return "mag_soft_iron must be invertible with condition number <= 10 (got singular values " +
           std::to_string(sv(0)) + ", " + std::to_string(sv(1)) + ", " + std::to_string(sv(2)) +
           ")";
  }
  if (mag_soft_iron.determinant() <= 0) {
    return "mag_soft_iron must have a positive determinant (it must not mirror the field)";
  }
  return {};
}

void Calibration::apply(const RawSample& raw, ImuSample* out) const {
  const Eigen::Matrix3d r_imu = imu_axes.matrix();
  const Eigen::Matrix3d r_mag = mag_axes.matrix();
  out->seq = raw.seq;
  out->gyro_rps = r_imu * gyro_scale.cwiseProduct(raw.gyro_rps - gyro_bias_rps);
  out->accel_mps2 = r_imu * accel_scale.cwiseProduct(raw.accel_mps2 - accel_bias_mps2);
  out->has_accel = true;
  out->has_gyro = true;
  out->has_mag = raw.has_mag;
  out->mag_ut = raw.has_mag ? Eigen::Vector3d(r_mag * (mag_soft_iron * (raw.mag_ut - mag_hard_iron_ut)))
                            : Eigen::Vector3d::Zero();
  out->pressure_pa = raw.pressure_pa;
  out->has_pressure = raw.has_pressure;
  out->temperature_c = raw.temperature_c;
  out->has_temperature = raw.has_temperature;
}

RawSample Calibration::invert(const ImuSample& s) const {
  RawSample r;
  r.seq = s.seq;
  r.gyro_rps = (imu_axes.matrix().transpose() * s.gyro_rps).cwiseQuotient(gyro_scale) + gyro_bias_rps;
  r.accel_mps2 =
      (imu_axes.matrix().transpose() * s.accel_mps2).cwiseQuotient(accel_scale) + accel_bias_mps2;
  r.has_mag = s.has_mag;
  if (s.has_mag) {
    r.mag_ut = mag_soft_iron.inverse() * (mag_axes.matrix().transpose() * s.mag_ut) + mag_hard_iron_ut;
  }
  r.has_pressure = s.has_pressure;
  r.pressure_pa = s.pressure_pa;
  r.has_temperature = s.has_temperature;
  r.temperature_c = s.temperature_c;
  return r;
}

}  // namespace poise::imu
