#include "poise/record/replay_schedule.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace poise::record {

ReplayClock ReplayClock::steady() {
  ReplayClock c;
  c.now_ns = [] {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
  };
  c.sleep_until_ns = [](int64_t t) {
    std::this_thread::sleep_until(std::chrono::steady_clock::time_point(std::chrono::nanoseconds(t)));
  };
  return c;
}

ScheduleStats run_schedule(const McapReader& reader, const ScheduleOptions& options,
                           const ReplayClock& clock,
                           const std::function<bool(const MessageView&)>& publish) {
  if (!(options.rate > 0.0) || !std::isfinite(options.rate)) {
    throw std::invalid_argument("replay rate must be a positive number");
  }
  ScheduleStats stats;
  const FileReport& report = reader.report();
  ReadFilter filter;
  filter.topics = options.topics;
  if (options.start_s) {
    filter.start_ns = report.start_ns + static_cast<uint64_t>(std::max(0.0, *options.start_s) * 1e9);
  }
  if (options.end_s) {
    filter.end_ns = report.start_ns + static_cast<uint64_t>(std::max(0.0, *options.end_s) * 1e9);
  }
  auto stopped = [&] { return options.should_stop && options.should_stop(); };
  constexpr int64_t kPollNs = 100'000'000;
  const int64_t t_begin = clock.now_ns();
  bool stop = false;
  do {
    MessageCursor cursor = reader.messages(filter);
    const int64_t t_pass = clock.now_ns();
    std::optional<uint64_t> first_log;
    uint64_t last_log = 0;
    bool any = false;
    while (const MessageView* m = cursor.next()) {
      if (stopped()) {
        stop = true;
        break;
      }
      any = true;
      if (!first_log) {
        first_log = filter.start_ns ? std::min(*filter.start_ns, m->log_time_ns) : m->log_time_ns;
      }
      last_log = m->log_time_ns;
      if (!options.as_fast_as_possible) {
        const double offset_ns =
            static_cast<double>(m->log_time_ns - *first_log) / options.rate;
        const int64_t target = t_pass + static_cast<int64_t>(offset_ns);
        for (int64_t now = clock.now_ns(); now < target; now = clock.now_ns()) {
          clock.sleep_until_ns(std::min(target, now + kPollNs));
          if (stopped()) {
            stop = true;
            break;
          }
        }
        if (stop) {
          break;
        }
        stats.max_late_s = std::max(stats.max_late_s, static_cast<double>(clock.now_ns() - target) * 1e-9);
      }
      if (publish(*m)) {
        ++stats.delivered;
        ++stats.per_topic[m->channel->topic];
      } else {
        ++stats.rejected;
      }
    }
    for (const std::string& p : cursor.problems()) {
      if (std::find(stats.problems.begin(), stats.problems.end(), p) == stats.problems.end()) {
        stats.problems.push_back(p);
      }
    }
    if (first_log) {
      stats.recorded_span_s = static_cast<double>(last_log - *first_log) * 1e-9;
    }
    if (!stop) {
      ++stats.passes;
    }
    if (!any) {
      break;  // nothing selected: looping would spin
    }
  } while (options.loop && !stop);
  stats.elapsed_s = static_cast<double>(clock.now_ns() - t_begin) * 1e-9;
  return stats;
}

}  // namespace poise::record
