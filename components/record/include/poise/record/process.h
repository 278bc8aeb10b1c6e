// `poise process`: runs attitude filters directly on a recording: no DDS, no clocks, no sleeps.
// The same input and filters give a byte-identical output file (the writer's chunk clock is the
// recording's log time).
//
// Output: every input message copied through unchanged (same channels, times, bytes), plus one
// channel `<prefix><name>` (AttitudeEstimate) per filter with one estimate per accepted IMU
// sample once the filter is initialised: log_time = the IMU message's log time, publish_time =
// header.stamp_ns = the sample stamp. Filled fields: header, sensor_id, filter_id, q_world_body,
// roll/pitch/yaw (ZYX); the others stay 0 (the AttitudeFilter interface has no more).
#pragma once

#include "poise/core/attitude_filter.h"

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

namespace poise::record {

struct ProcessFilter {
  std::string name;  ///< instance name: output topic suffix and filter_id
  std::unique_ptr<AttitudeFilter> filter;
};

struct ProcessOptions {
  std::string input;
  std::string output;
  std::string imu_topic = "imu";
  std::string output_prefix = "processed/attitude/";
  bool copy_input = true;
  std::ostream* progress = nullptr;  ///< percent lines; none when null
};

struct ProcessStats {
  uint64_t input_messages = 0;
  uint64_t imu_samples = 0;
  uint64_t undecodable = 0;  ///< IMU payloads that are malformed (skipped, counted)
  std::vector<std::string> undecodable_details;  ///< the first 10: position (index, offset) + why
  uint64_t damaged_chunks = 0;  ///< chunks that could not be read while processing (skipped)
  std::map<std::string, uint64_t> estimates;  ///< per filter
  std::map<std::string, uint64_t> rejected;   ///< per filter: update() returned false
  bool input_complete = true;
  std::vector<std::string> input_problems;
  uint64_t corrupt_in_file = 0;  ///< FileReport::corrupt of the input
  /// Corrupt chunks or bytes: part of the input could not be read (a file merely cut short by a
  /// killed recorder is incomplete, not damaged).
  [[nodiscard]] bool input_damaged() const { return corrupt_in_file > 0 || damaged_chunks > 0; }
};

/// Throws ReadError (input) or WriteError (output).
ProcessStats process_recording(const ProcessOptions& options, std::vector<ProcessFilter>& filters);

}  // namespace poise::record
