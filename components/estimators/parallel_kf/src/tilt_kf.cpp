#include "poise/parallel_kf/tilt_kf.h"

namespace poise {

TiltKf::TiltKf(const TiltKfParams& params) : params_(params), kf_(params.direction_params()) {}

void TiltKf::reset(const Eigen::Vector3d& up_body) {
  Eigen::Vector3d z;
  if (!safe_normalize(up_body, z)) {
    initialized_ = false;
    return;
  }
  kf_.reset(z, params_.initial_var_tilt, params_.initial_var_accel);
  innovation_.setZero();
  z_prior_ = kf_.u();
  initialized_ = true;
}

bool TiltKf::predict(const Eigen::Vector3d& gyro_rps, double dt_s) {
  if (!initialized_ || !gyro_rps.allFinite() || !std::isfinite(dt_s) || dt_s <= 0.0) {
    return false;
  }
  kf_.predict(gyro_rps, dt_s);
  return true;
}

bool TiltKf::correct(const Eigen::Vector3d& accel_mps2, double extra_var_mps2sq) {
  if (!accel_mps2.allFinite() || !std::isfinite(extra_var_mps2sq) || extra_var_mps2sq < 0.0) {
    return false;
  }
  if (!initialized_) {
    reset(accel_mps2);
    return initialized_;
  }
  z_prior_ = kf_.u();
  innovation_ = kf_.correct(accel_mps2, params_.gravity_mps2, extra_var_mps2sq);
  return true;
}

bool TiltKf::update(const Eigen::Vector3d& gyro_rps, const Eigen::Vector3d& accel_mps2, double dt_s) {
  if (!gyro_rps.allFinite() || !accel_mps2.allFinite() || !std::isfinite(dt_s) || dt_s <= 0.0) {
    return false;
  }
  if (!initialized_) {
    reset(accel_mps2);
    return initialized_;
  }
  kf_.predict(gyro_rps, dt_s);
  return correct(accel_mps2);
}

}  // namespace poise
