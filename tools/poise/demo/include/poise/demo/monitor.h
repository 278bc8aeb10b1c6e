// PipelineMonitor: subscribes to everything a poise pipeline publishes (attitude of every filter,
// simulated truth, altitude, camera, diagnostics) and keeps (1) the latest values for a live
// dashboard and (2) time series for the report. Estimates are matched to truth by the IMU seq
// they carry (header.seq), so comparisons are exact even though topics arrive independently.
#pragma once

#include "poise/core/consistency.h"
#include "poise/dds/participant.h"
#include "poise/dds/topics.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace poise::demo {

/// One estimate (or truth) sample.
struct AttitudePoint {
  double t_s = 0.0;             ///< seconds since the monitor started (receive time)
  int64_t stamp_ns = 0;
  Eigen::Quaterniond q{1, 0, 0, 0};
  Eigen::Vector3d rpy_rad{0, 0, 0};
  double disturbance_norm_ut = 0.0;
  bool mag_trusted = false;
  double latency_ms = 0.0;      ///< receive time - sample stamp (same host clock)
};

struct AltitudePoint {
  double t_s = 0.0;
  uint32_t seq = 0;             ///< IMU seq of the sample (header.seq): matches the truth's
  double height_m = 0.0;
  double vertical_velocity_mps = 0.0;
  double baro_height_m = 0.0;
  bool stationary = false;
};

/// One position sample (a filter's pose or the simulated truth's).
struct PositionPoint {
  double t_s = 0.0;             ///< seconds since the monitor started (receive time)
  uint32_t seq = 0;             ///< IMU seq of the sample (header.seq): matches the truth's
  Eigen::Vector3d p_m{0, 0, 0};  ///< position in the world (ENU), m
};

/// Per-filter accumulated figures.
struct FilterStats {
  uint64_t received = 0;
  double rate_hz = 0.0;
  double error_deg = 0.0;       ///< latest total attitude error vs truth, deg (NaN: no truth)
  double sum_sq_error = 0.0;    ///< for the RMSE
  uint64_t compared = 0;
  NeesSummary nees;             ///< the published attitude_covariance against truth
  std::vector<double> latencies_ms;
  AttitudePoint latest;
};

class PipelineMonitor {
 public:
  PipelineMonitor(dds::Participant& participant, const dds::TopicNames& topics,
                  const std::vector<std::string>& filters);
  ~PipelineMonitor();

  /// Filters (e.g. "parallel_kf") to figures; thread-safe snapshot.
  [[nodiscard]] std::map<std::string, FilterStats> filter_stats() const;
  /// Time series per filter ("truth" included), altitude ("altitude", "truth").
  [[nodiscard]] std::map<std::string, std::vector<AttitudePoint>> attitude_series() const;
  [[nodiscard]] std::map<std::string, std::vector<AltitudePoint>> altitude_series() const;
  /// Error of each filter vs truth over time: filter -> (t_s, error deg).
  [[nodiscard]] std::map<std::string, std::vector<std::pair<double, double>>> error_series() const;
  /// The same errors by IMU seq: filter -> seq -> error deg (for comparisons sample by sample).
  [[nodiscard]] std::map<std::string, std::map<uint32_t, double>> errors_by_seq() const;
  /// Positions per filter that publishes a pose (`pose/<filter>`) and "truth" (`truth/pose`).
  [[nodiscard]] std::map<std::string, std::vector<PositionPoint>> position_series() const;
  /// Position error of each pose filter vs truth over time (matched by IMU seq): filter -> (t_s, m).
  [[nodiscard]] std::map<std::string, std::vector<std::pair<double, double>>> position_errors() const;
  /// Camera: frames with a pose, tags in the last frame, last pose time.
  struct CameraStats {
    uint64_t frames = 0;
    uint64_t poses = 0;
    int tags_in_view = 0;
    double last_pose_t_s = -1.0;
    std::vector<std::pair<double, int>> tags_series;  ///< (t, tags in view)
  };
  [[nodiscard]] CameraStats camera_stats() const;
  /// Sum of the rejection counters reported on `diagnostics`, per component.
  [[nodiscard]] std::map<std::string, uint64_t> rejected_counts() const;
  [[nodiscard]] double elapsed_s() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Percentile (0..100) of a sample (copied, nth_element); NaN when empty.
double percentile(std::vector<double> values, double p);

}  // namespace poise::demo
