// The comparison `poise process` prints: each processed estimate (processed/<topic>) against the
// live estimate recorded on <topic> with the same sensor_id, seq and stamp, and both against the
// simulator's truth (truth/attitude, truth/pose, truth/altitude) with the same seq, when the
// recording has it. Attitude: angle between the quaternions (RMSE, largest), its heading part and
// the consistency of the published covariance against truth (median NEES, % inside the 95 %
// ellipsoid, poise/core/consistency.h); when the
// magnetometer was trusted (mag_trusted) or vision fused (SOURCE_VISION in sources_fused)
// differently. Pose: distance between positions. Altitude: height difference.
#pragma once

#include "poise/core/consistency.h"

#include <cstdint>
#include <string>
#include <vector>

namespace poise::record {

struct Interval {
  double start_s = 0.0;  ///< seconds from the first stamp of the series
  double end_s = 0.0;
  uint64_t samples = 0;
};

/// Samples where a yes/no (trusted, fused) differs between processed and live, as intervals.
struct FlagDifference {
  uint64_t processed_yes = 0;   ///< matched samples where processed says yes
  uint64_t live_yes = 0;        ///< matched samples where live says yes
  uint64_t processed_only = 0;  ///< processed yes, live no
  uint64_t live_only = 0;       ///< live yes, processed no
  std::vector<Interval> intervals;
};

/// A part of each processed series scored on its own (`poise process --window FROM,TO`): e.g. the
/// heading once a disturbance has left, in a cold start. Seconds from the series' first stamp.
struct CompareWindow {
  double from_s = 0.0;
  double to_s = -1.0;  ///< below from_s: no window
  [[nodiscard]] bool enabled() const { return to_s > from_s; }
  [[nodiscard]] bool contains(double t_s) const { return t_s >= from_s && t_s <= to_s; }
};

/// Attitude against truth inside the window.
struct WindowFigures {
  uint64_t samples = 0;         ///< processed estimates inside it with a truth sample
  double heading_rmse = 0.0;    ///< deg
  double rmse = 0.0;            ///< deg, the whole rotation
  NeesSummary nees;
};

struct SeriesComparison {
  std::string kind;       ///< "attitude", "pose", "altitude"
  std::string topic;      ///< the live topic, e.g. attitude/selective_ekf
  std::string sensor_id;
  std::string unit;       ///< "deg" (attitude), "m" (pose, altitude)
  uint64_t processed = 0;  ///< processed estimates
  uint64_t live = 0;       ///< recorded live estimates
  uint64_t matched = 0;    ///< processed with a live one of the same seq and stamp
  double rmse = 0.0;       ///< processed - live, in `unit`
  double largest = 0.0;
  double largest_at_s = 0.0;  ///< seconds from the first stamp of the series
  std::string truth_topic;    ///< empty when the recording has no truth for it
  uint64_t truth_matched = 0;           ///< processed estimates with a truth sample of the same seq
  uint64_t truth_matched_live = 0;      ///< live estimates with one
  double processed_truth_rmse = 0.0;    ///< in `unit`
  double live_truth_rmse = 0.0;
  /// Attitude only: heading part of the error against truth (BROAD's heading), RMSE deg
  double processed_truth_heading_rmse = 0.0;
  double live_truth_heading_rmse = 0.0;
  /// Attitude only: NEES of the published attitude_covariance against truth
  NeesSummary processed_nees;
  NeesSummary live_nees;
  FlagDifference mag_trust;     ///< attitude only
  FlagDifference vision_fused;  ///< attitude only
  CompareWindow window;         ///< the window scored (enabled() false: none)
  WindowFigures in_window;      ///< attitude only, processed against truth
};

/// Compares every processed/<topic> of `file` (what `poise process` wrote) with <topic> and truth.
/// With an enabled `window`, each processed attitude series is also scored inside it.
std::vector<SeriesComparison> compare_processed(const std::string& file,
                                               const std::string& prefix = "processed/",
                                               const CompareWindow& window = {});
/// "median NEES x, y % inside the 95 % ellipsoid" (or that there was no usable covariance).
std::string format_nees(const NeesSummary& nees);
/// The printed summary (one block per series).
std::string format_comparison(const std::vector<SeriesComparison>& series);

}  // namespace poise::record
