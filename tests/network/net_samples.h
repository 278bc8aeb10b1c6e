// Deterministic sample contents shared by the network test peers (poise_net_node), the Cyclone DDS
// reader and the tests that check what arrived: every field is a function of the sequence number,
// so a receiver can verify each sample exactly (wire compatibility, no silent corruption).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

namespace poise::nettest {

/// IMU sample fields for sequence number `seq` (SI units, as in msg::ImuSample).
struct ImuValues {
  std::array<double, 3> accel_mps2;
  std::array<double, 3> gyro_rps;
  std::array<double, 3> mag_ut;
  double pressure_pa;
  double temperature_c;
};

inline ImuValues imu_values(uint32_t seq) {
  const double s = static_cast<double>(seq % 1000U);
  return {{0.25 + 1e-3 * s, -0.5, 9.80665},
          {1e-4 * s, 0.002, -0.003},
          {20.5, -3.25, -40.0 - 1e-2 * s},
          101325.0 - s,
          24.5};
}

/// VisionPose fields for sequence number `seq`.
struct VisionValues {
  std::array<double, 3> position_m;
  std::array<double, 4> q_wxyz;
  double covariance_diag;
  double reprojection_rms_px;
  std::array<int32_t, 3> tag_ids;
};

inline VisionValues vision_values(uint32_t seq) {
  const double s = static_cast<double>(seq % 1000U);
  return {{1.0 + 1e-3 * s, -2.0, 0.5},
          {0.5, 0.5, -0.5, 0.5},
          1e-4,
          0.75,
          {3, 7, static_cast<int32_t>(11 + seq % 5U)}};
}

/// Marker placed in sensor_id by the capture tests: found in plain RTPS traffic, never in encrypted.
inline constexpr const char* kMarkerSensorId = "poise-wire-marker-5e1f";

}  // namespace poise::nettest

namespace poise::nettest {

/// PoseEstimate fields for sequence number `seq`: covariance(i, j) = 100 * i + j + 1 (9x9,
/// row-major), so every element's origin is recognisable after a re-layout.
struct PoseValues {
  std::array<double, 3> position_m;
  std::array<double, 4> q_wxyz;
};

inline PoseValues pose_values(uint32_t seq) {
  const double s = static_cast<double>(seq % 1000U);
  return {{10.0 + 1e-3 * s, -5.0, 1.25}, {0.5, -0.5, 0.5, 0.5}};
}

inline double pose_covariance(std::size_t row, std::size_t col) {
  return static_cast<double>(100 * row + col + 1);
}

}  // namespace poise::nettest
