// Fuzz target for the IMU filters' update (issue 19): arbitrary doubles, stamps and flags go to
// the parallel KF, Gauss-Newton, the selective EKF, the altitude filter and the vehicle
// estimator. Invariant (abort on violation): after every update each initialised filter's
// q_world_body is finite and unit-norm, the altitude filter's height and velocity are finite, and
// every covariance passes the per-sample state-health check (finite variances, none negative:
// poise/core/state_health.h; a filter that fails it resets itself); a sample the filter cannot
// use is rejected, never integrated.
//
// Input: records of 1 flag byte, a stamp and 9 values (gyro, accel, mag):
//   flag & 1: stamp = 8 raw bytes (any int64: negative, -2^63, INT64_MAX; the shared sample
//             check refuses stamps outside [0, 2^62] ns), else stamp += 2 bytes x 10 us
//             (wrapping as unsigned);
//   flag & 2: values = 8 raw bytes each (any double, NaN and inf included), else 2 bytes each,
//             scaled to plausible ranges (gyro 1e-3 rad/s, accel 1e-3 m/s^2, mag 1e-2 uT);
//   flag & 4: no magnetometer; flag & 8: no gyro; flag & 16: no accelerometer;
//   flag & 32: a pressure (mag.x: raw, else 101325 Pa + 100 x mag.x); the vehicle estimator gets
//             the IMU's x/y specific force, z rate and magnetometer with speed |mag.y|.
#include "poise/altitude/altitude_filter.h"
#include "poise/core/state_health.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/vehicle/vehicle_estimator.h"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>

namespace {

void check(bool ok) {
  if (!ok) std::abort();
}

struct Reader {
  const uint8_t* p;
  size_t n;
  bool take(void* out, size_t k) {
    if (n < k) return false;
    std::memcpy(out, p, k);
    p += k;
    n -= k;
    return true;
  }
};

void check_q(const poise::AttitudeFilter& f) {
  if (!f.initialized()) return;
  const Eigen::Quaterniond q = f.q_world_body();
  check(q.coeffs().allFinite());
  check(std::abs(q.norm() - 1.0) < 1e-6);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  poise::ParallelKfFilter pkf;
  poise::GaussNewtonFilter gn;
  poise::SelectiveEkfFilter ekf;
  poise::AttitudeFilter* filters[] = {&pkf, &gn, &ekf};
  poise::AltitudeFilter alt;
  poise::VehicleEstimator veh;
  Reader r{data, size};
  int64_t stamp = 0;
  uint32_t seq = 0;
  for (int records = 0; records < 4096; ++records) {
    uint8_t flag = 0;
    if (!r.take(&flag, 1)) break;
    if (flag & 1) {
      uint64_t raw = 0;
      if (!r.take(&raw, 8)) break;
      stamp = static_cast<int64_t>(raw);
    } else {
      uint16_t d = 0;
      if (!r.take(&d, 2)) break;
      stamp = static_cast<int64_t>(static_cast<uint64_t>(stamp) + d * 10000ULL);
    }
    double v[9];
    bool complete = true;
    for (int i = 0; i < 9 && complete; ++i) {
      if (flag & 2) {
        complete = r.take(&v[i], 8);
      } else {
        int16_t x = 0;
        complete = r.take(&x, 2);
        v[i] = x * (i < 3 ? 1e-3 : i < 6 ? 1e-3 : 1e-2);
      }
    }
    if (!complete) break;
    poise::ImuSample s;
    s.stamp_ns = stamp;
    s.seq = seq++;
    s.gyro_rps = Eigen::Vector3d(v[0], v[1], v[2]);
    s.accel_mps2 = Eigen::Vector3d(v[3], v[4], v[5]);
    s.mag_ut = Eigen::Vector3d(v[6], v[7], v[8]);
    s.has_mag = (flag & 4) == 0;
    s.has_gyro = (flag & 8) == 0;
    s.has_accel = (flag & 16) == 0;
    s.has_pressure = (flag & 32) != 0;
    s.pressure_pa = (flag & 2) ? v[6] : 101325.0 + 100.0 * v[6];
    for (poise::AttitudeFilter* f : filters) {
      (void)f->update(s);
      check_q(*f);
    }
    if (pkf.initialized()) {
      check(poise::covariance_ok(pkf.core().tilt_covariance(), false));
      check(poise::covariance_ok(pkf.core().heading_covariance(), false));
    }
    if (ekf.initialized()) {
      check(poise::covariance_ok(ekf.core().state().P, false));
    }
    // a stamp outside [0, 2^62] ns (the shared check) is refused whatever the values
    const bool wild_stamp = s.stamp_ns < 0 || s.stamp_ns > poise::kMaxStampNs;
    check(!(alt.update(s) && wild_stamp));
    if (alt.estimate().valid) {
      check(std::isfinite(alt.estimate().height_m) && std::isfinite(alt.estimate().vertical_velocity_mps));
      check(poise::covariance_ok(alt.kf_covariance(), false));
      check(poise::covariance_ok(alt.tilt().covariance(), false));
    }
    check(!(veh.update(poise::vehicle_sample_from_imu(s, true, std::abs(v[7]))) && wild_stamp));
    if (veh.estimate().valid) {
      const Eigen::Quaterniond q = veh.estimate().q_world_body;
      check(q.coeffs().allFinite() && std::abs(q.norm() - 1.0) < 1e-6);
      check(poise::covariance_ok(veh.ekf_covariance(), false));
    }
  }
  return 0;
}
