// IMU group delay against an orientation reference (motion capture, or a camera's tag poses).
//
// An IMU's internal low-pass filter delays its measurements: the gyro sample stamped t describes
// the rotation at about t - d. Integrating the gyro from reference[k] over a short window and
// comparing with the reference at the window's end, shifted by a trial lag s, is best when s
// matches the delay: the estimate is d = the lag minimising the RMS of that comparison
// (sub-sample resolution, parabolic refinement of a grid search). Pure: no I/O.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace poise::eval {

struct ImuDelayOptions {
  double rate_hz = 0.0;          ///< sample rate of gyro and reference (same index grid)
  int window_samples = 20;       ///< gyro integration window (about 70 ms at 286 Hz)
  int stride = 3;                ///< windows start every `stride` samples
  double max_lag_samples = 10.0; ///< searched lags: [-max, +max] samples
  double step_samples = 0.1;
  double min_rate_rps = 0.3;     ///< windows whose mean |gyro| is below this carry no timing
};

struct ImuDelayEstimate {
  bool ok = false;               ///< false: too few windows or the minimum lies on the search edge
  double delay_s = 0.0;          ///< positive: the IMU lags the reference
  double delay_samples = 0.0;
  double rms_at_delay_deg = 0.0; ///< window-end error at the estimated delay
  double rms_at_zero_deg = 0.0;  ///< the same with no delay
  size_t windows = 0;
  const char* why = "";          ///< reason when !ok
};

/// gyro_rps[k] and q_ref_wxyz[k] share the index grid; NaN reference rows are skipped; `use[k]`
/// (optional, empty = all) selects windows (e.g. BROAD's movement flag).
ImuDelayEstimate estimate_imu_delay(const std::vector<Eigen::Vector3d>& gyro_rps,
                                    const std::vector<Eigen::Vector4d>& q_ref_wxyz,
                                    const std::vector<uint8_t>& use, const ImuDelayOptions& options);

}  // namespace poise::eval
