// Component `ros2_bridge`: poise <-> ROS 2 over plain DDS, no ROS installation needed
// (docs/ROS2.md). Its parameters are a small map (host-file `params`, or `poise ros2-bridge
// --config MAP.yaml`):
//   namespace: /poise            # ROS names of the outputs: <namespace>/...
//   world_frame: world           # header.frame_id of estimates, tf parent (ENU, REP 103)
//   body_frame: imu_link         # frame of the IMU's axes: raw IMU frame_id, odometry/tf child
//   stamps: realtime             # header.stamp = stamp_ns + (CLOCK_REALTIME - CLOCK_MONOTONIC at
//                                #   start), what ROS nodes compare with now(); `sensor`: = stamp_ns
//   out:
//     attitude: [parallel_kf]    # attitude/<f> -> <namespace>/<f>/imu (sensor_msgs/Imu)
//     pose: [selective_ekf]      # pose/<f> -> <namespace>/<f>/pose (PoseWithCovarianceStamped)
//                                #   and <namespace>/<f>/odom (nav_msgs/Odometry)
//     imu: true                  # imu -> <namespace>/imu/data_raw (Imu), /imu/mag
//                                #   (MagneticField, T), /imu/pressure (FluidPressure, Pa)
//     altitude: true             # altitude -> <namespace>/altitude/odom (Odometry)
//     tf: attitude/parallel_kf   # world -> body on /tf from attitude/<f> or pose/<f>; "" = none
//   in:                          # a ROS 2 driver's IMU -> poise `imu` (absent: no input)
//     imu: /imu/data             # sensor_msgs/Imu (required for input)
//     mag: /imu/mag              # sensor_msgs/MagneticField (optional)
//     pressure: /imu/pressure    # sensor_msgs/FluidPressure (optional)
//     pair_tolerance_s: 0.0025   # pairing of each side stream with the Imu by stamp
//     stale_s: 0.5               # a side stream this far behind is not waited for
// Without `out`, the default publishes attitude/parallel_kf, the raw IMU and /tf from
// attitude/parallel_kf. QoS: outputs reliable + volatile (what a default ROS 2 subscription and
// tf2's listener match), inputs best-effort (accepts ROS sensor-data and reliable publishers).
// Counters (out, pairings, rejections by reason) in status() and on `diagnostics` once a second.
#pragma once

#include "poise/ros2_bridge/convert.h"
#include "poise/ros2_bridge/input.h"
#include "poise/runtime/component.h"

#include <string>
#include <vector>

namespace poise::ros2 {

struct BridgeConfig {
  std::string ros_namespace = "/poise";
  Frames frames;
  bool realtime_stamps = true;
  std::vector<std::string> attitude{"parallel_kf"};
  std::vector<std::string> pose;
  bool imu = true;
  bool altitude = false;
  std::string tf = "attitude/parallel_kf";  ///< "attitude/<f>", "pose/<f>" or "" (none)
  std::string in_imu;                       ///< ROS names; empty: none
  std::string in_mag;
  std::string in_pressure;
  double pair_tolerance_s = 0.0025;
  double stale_s = 0.5;
};

/// Parses and validates the map; throws runtime::ConfigError naming `origin` and the key.
BridgeConfig parse_bridge_config(const YAML::Node& params, const std::string& origin);

/// One output and its DDS topic, for the docs and tests: (ROS name, DDS topic, ROS type).
struct BridgedTopic {
  std::string ros_name;
  std::string dds_topic;
  std::string ros_type;  ///< e.g. "sensor_msgs/msg/Imu"
  std::string poise_topic;  ///< the poise topic it comes from or goes to
};
/// Every ROS topic `config` publishes or reads (poise topic names from `names`).
std::vector<BridgedTopic> bridged_topics(const BridgeConfig& config, const dds::TopicNames& names);

void register_ros2_bridge(runtime::ComponentRegistry& registry);

}  // namespace poise::ros2
