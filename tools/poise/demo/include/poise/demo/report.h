// The demo report: PNG charts (estimate vs truth per filter, each filter's error on its own scale
// with the scripted episodes, the selective EKF's position and path, magnetic disturbance and
// trust, altitude) and an index.html with the summary tables and what every figure means.
#pragma once

#include "poise/demo/monitor.h"

#include <string>
#include <vector>

namespace poise::demo {

/// A scripted episode shown as a band on the charts (times in seconds since the start).
struct Episode {
  double start_s = 0.0;
  double end_s = 0.0;
  std::string label;
  int colour = 0;  ///< 0 magnet, 1 tag lost, 2 stairs
};

struct ReportInput {
  std::string title;
  std::vector<std::string> filters;
  std::vector<Episode> episodes;
  std::vector<std::string> notes;  ///< free lines (configuration, devices)
  /// The IMU is the simulator, which publishes the truth: errors are computed and charted. False
  /// with real hardware (--port): estimates only, and the report says why there is no error.
  bool simulated_truth = true;
};

/// Writes the charts and index.html into `dir` (created if needed); returns the index path.
/// Throws std::runtime_error when the directory cannot be written.
std::string write_report(const std::string& dir, const ReportInput& input, const PipelineMonitor& monitor);

}  // namespace poise::demo
