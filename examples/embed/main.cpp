// A program that uses the installed poise cores (no DDS): the parallel Kalman filter and the
// selective EKF on a sensor tilted 20 deg in roll that turns about the vertical at 10 deg/s after
// 2 s at rest. It prints both estimates beside the truth and exits 0 when both are within 2 deg.
#include <poise/parallel_kf/parallel_kf.h>
#include <poise/selective_ekf/selective_ekf.h>

#include <cmath>
#include <cstdint>
#include <cstdio>

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr double kRateHz = 100.0;
constexpr double kRestS = 2.0;
constexpr double kTurnS = 6.0;
constexpr double kTurnRate = 10.0 * kDeg;  // rad/s about world up
constexpr double kRoll = 20.0 * kDeg;
constexpr double kTolDeg = 2.0;

double angle_deg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return 2.0 * std::acos(std::min(1.0, std::abs(a.dot(b)))) / kDeg;
}

}  // namespace

int main() {
  const Eigen::Quaterniond tilt(Eigen::AngleAxisd(kRoll, Eigen::Vector3d::UnitX()));
  const Eigen::Vector3d gravity_up(0.0, 0.0, 9.81);   // specific force at rest, ENU, m/s^2
  const Eigen::Vector3d field(0.0, 20.0, -45.0);      // Earth's field, ENU (north = +y), uT
  poise::ParallelKf pkf;                              // the shipped default configuration
  poise::SelectiveEkf sekf;                           // IMU only (no vision pose given)
  Eigen::Quaterniond truth = tilt;
  const int n = static_cast<int>((kRestS + kTurnS) * kRateHz);
  for (int k = 0; k < n; ++k) {
    const double t = k / kRateHz;
    const double yaw = t < kRestS ? 0.0 : kTurnRate * (t - kRestS);
    truth = Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())) * tilt;  // q_world_body
    poise::ImuSample s;
    s.stamp_ns = static_cast<int64_t>(k) * 10'000'000;  // the sensor's clock, ns
    s.seq = static_cast<uint32_t>(k);
    s.gyro_rps = t < kRestS ? Eigen::Vector3d::Zero() : Eigen::Vector3d(tilt.conjugate() * (kTurnRate * Eigen::Vector3d::UnitZ()));
    s.accel_mps2 = truth.conjugate() * gravity_up;
    s.mag_ut = truth.conjugate() * field;
    s.has_mag = true;  // a 9-axis sensor says so (the default is no magnetometer)
    pkf.update(s);
    sekf.update_imu(s);
  }
  const double e_pkf = angle_deg(pkf.q_world_body(), truth);
  const double e_sekf = angle_deg(sekf.q_world_body(), truth);
  std::printf("parallel_kf   error %.3f deg\nselective_ekf error %.3f deg\n", e_pkf, e_sekf);
  const bool ok = e_pkf < kTolDeg && e_sekf < kTolDeg;
  std::printf("%s (tolerance %.1f deg)\n", ok ? "ok" : "FAILED", kTolDeg);
  return ok ? 0 : 1;
}
