// Replay timing, without DDS: hands each message of a recording to a callback at its recorded
// log time scaled by a rate, on an injected clock (so timing is testable in simulated time).
#pragma once

#include "poise/record/mcap.h"

#include <functional>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace poise::record {

/// A monotonic clock and a way to wait on it (both in ns). Default: steady_clock + sleep.
struct ReplayClock {
  std::function<int64_t()> now_ns;
  std::function<void(int64_t)> sleep_until_ns;
  static ReplayClock steady();
};

struct ScheduleOptions {
  double rate = 1.0;               ///< 2.0 = twice as fast as recorded
  std::optional<double> start_s;   ///< skip messages before first log time + start_s
  std::optional<double> end_s;     ///< stop after first log time + end_s
  std::set<std::string> topics;    ///< empty = all
  bool loop = false;               ///< start again at the end (until stopped)
  bool as_fast_as_possible = false;
  std::function<bool()> should_stop;  ///< polled between messages and at least every 100 ms
};

struct ScheduleStats {
  uint64_t delivered = 0;            ///< messages handed to the callback
  uint64_t rejected = 0;             ///< callback returned false
  std::map<std::string, uint64_t> per_topic;
  int passes = 0;                    ///< completed passes over the file
  double recorded_span_s = 0.0;      ///< log time covered by one pass
  double elapsed_s = 0.0;            ///< clock time taken
  double max_late_s = 0.0;           ///< worst delay of a message behind its scheduled time
  std::vector<std::string> problems; ///< from the reader (corrupt chunks met while replaying)
};

/// Calls PUBLISH(message) for every selected message at clock time
///   t_pass_start + (log_time - t_first) / rate
/// (t_first = the first selected log time of the file) or immediately when as fast as possible.
ScheduleStats run_schedule(const McapReader& reader, const ScheduleOptions& options,
                           const ReplayClock& clock,
                           const std::function<bool(const MessageView&)>& publish);

}  // namespace poise::record
