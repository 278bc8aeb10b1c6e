// Component `sim_imu`: the simulated serial IMU (the embedded default device). Streams the poise
// serial protocol in real time on a pseudo-terminal exposed at `link` (a symlink, like
// /dev/ttyACM0) from the sensor simulator, optionally with injected faults, and publishes the
// simulated truth on DDS so dashboards and tests can compare estimates with it:
//   truth/attitude  (AttitudeEstimate: q_world_body, external acceleration, magnetic disturbance)
//   truth/pose      (PoseEstimate: position, velocity, q_world_body)
//   truth/altitude  (AltitudeEstimate: height above the start, vertical velocity and acceleration)
// Truth samples carry the seq of the serial line they belong to, and the host time at which the
// line was written as stamp, so they match the driver's ImuSample by seq.
//
// Parameters: link (required), scenario (sensor simulator scenario, default "demo"), rate_hz (200),
// seed (1), faults (FaultSpec text, default none), duration_s (0 = endless), publish_truth (true).
#pragma once

#include "poise/runtime/component.h"
#include "poise/sim/sensor_simulator.h"

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace poise::simulated {

struct SimImuParams {
  std::string link;
  std::string scenario = "demo";
  double rate_hz = 200.0;
  uint64_t seed = 1;
  std::string faults;
  double duration_s = 0.0;
  bool publish_truth = true;
  /// Send the $INF line of a sensor without delay (`$INF,1,SIM,,0,0`, at start and once a second,
  /// as the GY-87 firmware sends its own), so the driver publishes delay 0 on imu_info and every
  /// filter uses it; false: a sensor that says nothing (filters assume half a sample).
  bool sensor_info = true;
};
SimImuParams sim_imu_params(const runtime::ComponentSpec& spec);

/// Truth topic names (under the host's topic names).
inline constexpr const char* kTruthAttitudeTopic = "truth/attitude";
inline constexpr const char* kTruthPoseTopic = "truth/pose";
inline constexpr const char* kTruthAltitudeTopic = "truth/altitude";

void register_sim_imu(runtime::ComponentRegistry& registry);

}  // namespace poise::simulated
