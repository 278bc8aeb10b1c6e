// `poise replay`: republishes a recording over DDS, payloads byte for byte (raw type under the
// recorded type name), with the recorded timing scaled by a rate (see replay_schedule.h).
#pragma once

#include "poise/record/replay_schedule.h"

#include <cstddef>
#include <ostream>
#include <string>

namespace poise::record {

struct ReplayOptions {
  std::string input;
  ScheduleOptions schedule;
  int domain = 0;
  std::string participant_profile;  ///< "" = $POISE_DDS_PROFILE / poise_default
  /// Before publishing, wait up to this long for every topic to have a subscriber.
  double wait_for_subscribers_s = 1.0;
  ReplayClock clock = ReplayClock::steady();
  std::ostream* log = nullptr;  ///< stderr when null
  /// At most this many DDS writers (one per channel carrying messages, made when its first
  /// message is due or before the replay for the channels the file counts); the messages of
  /// further channels are skipped and counted (ReplayStats::over_limit_messages).
  std::size_t max_writers = 1024;
};

struct ReplayStats {
  ScheduleStats schedule;
  uint64_t write_failures = 0;  ///< DDS refused the sample (e.g. larger than the type allows)
  uint64_t malformed = 0;  ///< payloads not valid for their type: skipped (logged with position)
  std::vector<std::string> file_problems;  ///< what the reader recovered (empty if complete)
  bool complete = true;
  uint64_t corrupt_in_file = 0;  ///< FileReport::corrupt
  std::size_t writers = 0;              ///< DDS writers made (channels that carried messages)
  std::size_t channels_over_limit = 0;  ///< channels left out: max_writers reached
  uint64_t over_limit_messages = 0;     ///< their messages (not published)
  /// Corrupt chunks or bytes (in the file or met while replaying); a file cut short is not.
  [[nodiscard]] bool damaged() const { return corrupt_in_file > 0 || !schedule.problems.empty(); }
};

/// Opens the file (ReadError if it is not MCAP), creates one writer per selected channel and
/// replays. Throws poise::dds::DdsError on DDS setup failures.
ReplayStats replay(const ReplayOptions& options);

}  // namespace poise::record
