// The slow paths of check_imu_sample (poise/core/sample_check.h): the tests in their order, for a
// sample whose norms are not finite or not within the limits.
#include "poise/core/sample_check.h"

namespace poise {

RejectReason imu_values_reject(const ImuSample& s, const SampleLimits& lim) {
  if (!s.gyro_rps.allFinite()) {
    return RejectReason::kNonFiniteGyro;
  }
  if (!s.accel_mps2.allFinite()) {
    return RejectReason::kNonFiniteAccel;
  }
  if (!(s.gyro_rps.norm() <= lim.max_gyro_rps)) {
    return RejectReason::kGyroOutOfRange;
  }
  if (!(s.accel_mps2.norm() <= lim.max_accel_mps2)) {
    return RejectReason::kAccelOutOfRange;
  }
  if (!(s.accel_mps2.norm() >= lim.min_accel_norm_mps2)) {
    return RejectReason::kZeroAccel;
  }
  return RejectReason::kCount;
}

RejectReason mag_value_reject(const Eigen::Vector3d& mag_ut, const SampleLimits& lim) {
  const double norm = mag_ut.norm();
  if (!mag_ut.allFinite()) {
    return RejectReason::kNonFiniteMag;
  }
  if (!(norm >= lim.min_mag_norm_ut)) {
    return RejectReason::kZeroMag;
  }
  if (!(norm <= lim.max_mag_ut)) {
    return RejectReason::kMagOutOfRange;
  }
  return RejectReason::kCount;
}

}  // namespace poise
