// Which IMU group delay (imu_delay_s) an estimator step uses: the one its configuration gives
// explicitly (the component's `imu_delay_s` parameter, or the key in its filter file) wins; else
// the delay the IMU's driver publishes with the samples (`imu_info`, msg::ImuSensorInfo, from the
// firmware's $INF line: docs/SERIAL_PROTOCOL.md); else the configuration's default (NaN for the
// parallel KF and the selective EKF: not known, half a sample assumed).
#pragma once

#include "poise/runtime/component.h"

#include <string>

namespace poise::nodes {

class ImuDelayChoice {
 public:
  ImuDelayChoice() = default;
  /// `configured_s`: the delay the loaded parameters hold; `explicit_config`: the configuration set
  /// it (a published delay is then ignored).
  ImuDelayChoice(double configured_s, bool explicit_config)
      : in_use_s_(configured_s), explicit_(explicit_config) {}
  /// A delay published for the step's IMU (`what` describes its origin). True when the step must
  /// now use `delay_s` (not configured explicitly, and different from the delay in use).
  bool offer(double delay_s, const std::string& what);
  [[nodiscard]] double in_use_s() const { return in_use_s_; }
  [[nodiscard]] bool published_in_use() const { return published_; }
  /// "imu_delay_s 4.800 ms (published by the IMU driver: ...)", "(configured)", or "(default:
  /// nothing configured or published)".
  [[nodiscard]] std::string describe() const;

 private:
  double in_use_s_ = 0.0;
  bool explicit_ = false;
  bool published_ = false;
  std::string what_;
};

/// Whether the configuration of `spec` sets imu_delay_s: the component parameter `imu_delay_s`,
/// or the key in `filter_file` (top level, under `section:`, or dotted `section.imu_delay_s`).
/// An empty `filter_file` is not read.
bool imu_delay_configured(const runtime::ComponentSpec& spec, const std::string& filter_file,
                          const std::string& section);

}  // namespace poise::nodes
