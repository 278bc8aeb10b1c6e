// `poise process`: runs estimator components on a recording offline: no DDS, no clocks, no
// sleeps. Each component runs through the same step logic as its live node
// (poise/nodes/estimator_step.h: StepRunner around the component's EstimatorStep), fed with the
// recorded inputs it subscribes to live -- `imu`, `vision_pose` (at its capture stamp),
// `vehicle_input` -- in the order of their sample stamps (or, with ProcessOrder::kRecorded, in the
// order they were recorded). The same input and components give a byte-identical output file (the
// writer's chunk clock is the recording's log time).
//
// Output: every input message copied through unchanged (same channels, times, bytes), plus what
// the live components publish, under `<prefix>` + the live topic: processed/attitude/<filter>,
// processed/pose/<filter>, processed/altitude, processed/diagnostics. Each output keeps the seq and
// stamp of the IMU sample it was computed from; its log time is that sample's log time and its
// publish time the stamp. An attitude filter given alone (ProcessFilter, `--filter`) runs as a
// step that fills the quaternion, the Euler angles and the covariance (what the AttitudeFilter
// interface has; -1 in its first element, REP 145's unknown, for a filter without one).
#pragma once

#include "poise/core/attitude_filter.h"
#include "poise/dds/topics.h"
#include "poise/nodes/estimator_step.h"

#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

namespace poise::record {

/// An attitude filter alone (sensor_id and filter id = `name`).
struct ProcessFilter {
  std::string name;  ///< instance name: output topic suffix, filter_id and sensor_id
  std::unique_ptr<AttitudeFilter> filter;
  NorthReference north;  ///< outputs in true ENU (frame id enu_true) when a declination is set
};

/// A component run offline: its step and node parameters (diagnostics_rate_hz, diagnostics_every, ...).
struct ProcessComponent {
  std::unique_ptr<nodes::EstimatorStep> step;
  nodes::NodeParams params;
};

enum class ProcessOrder {
  kStamp,     ///< inputs in the order of their sample stamps (vision: capture stamp); ties: recorded
  kRecorded,  ///< inputs in the order the recording holds them (log time: arrival at the recorder)
};

struct ProcessOptions {
  std::string input;
  std::string output;
  dds::TopicNames topics;  ///< input topic names (imu, imu_info, vision_pose, vehicle_input)
  std::string output_prefix = "processed/";
  ProcessOrder order = ProcessOrder::kStamp;
  bool copy_input = true;
  /// The part of the recording processed, s from its first log time (FileReport::start_ns):
  /// messages logged before start_s or at or after end_s are neither run nor copied, as if the
  /// recording had been cut there (e.g. a cold start in the middle of a run). 0 / infinity: all.
  double start_s = 0.0;
  double end_s = std::numeric_limits<double>::infinity();
  /// Called as the work advances: `done` of `total` units (decoding, running the components and
  /// writing each count one unit per input message). Unset: no progress.
  std::function<void(uint64_t done, uint64_t total)> progress;
};

struct ProcessStats {
  uint64_t input_messages = 0;
  uint64_t imu_samples = 0;
  uint64_t vision_samples = 0;
  uint64_t vehicle_inputs = 0;
  uint64_t imu_gaps = 0;     ///< gaps in the recorded IMU's header.seq (per sensor, stamp order)
  uint64_t imu_missing = 0;  ///< samples those gaps leave out (live may have processed them)
  uint64_t undecodable = 0;  ///< input payloads that are malformed (skipped, counted)
  /// ImuSensorInfo messages on `imu_info` (the IMU's delay, given to every component before the
  /// first sample: a property of the sensor), and what each component then uses
  uint64_t imu_infos = 0;
  std::vector<std::string> imu_delay_notes;
  std::vector<std::string> undecodable_details;  ///< the first 10: position (index, offset) + why
  uint64_t damaged_chunks = 0;  ///< chunks that could not be read while processing (skipped)
  /// Inputs held at most to run them in stamp order (how far the stamp order strays from the
  /// file's order; 0 in recorded order): with the messages between them, all that is in memory.
  uint64_t reorder_window = 0;
  std::map<std::string, uint64_t> estimates;    ///< per component (sensor_id)
  std::map<std::string, uint64_t> rejected;     ///< per component: IMU samples its core rejected
  std::map<std::string, uint64_t> diagnostics;  ///< per component: FilterDiagnostics written
  std::map<std::string, uint64_t> per_topic;    ///< messages written per output topic
  bool input_complete = true;
  std::vector<std::string> input_problems;
  uint64_t corrupt_in_file = 0;  ///< FileReport::corrupt of the input
  /// Corrupt chunks or bytes: part of the input could not be read (a file merely cut short by a
  /// killed recorder is incomplete, not damaged).
  [[nodiscard]] bool input_damaged() const { return corrupt_in_file > 0 || damaged_chunks > 0; }
};

/// Throws ReadError (input) or WriteError (output).
ProcessStats process_recording(const ProcessOptions& options, std::vector<ProcessComponent>& components);
/// The same for attitude filters alone.
ProcessStats process_recording(const ProcessOptions& options, std::vector<ProcessFilter>& filters);

/// An attitude filter as a step (quaternion and Euler angles; sensor_id and filter id = name).
std::unique_ptr<nodes::EstimatorStep> filter_step(ProcessFilter filter);

}  // namespace poise::record
