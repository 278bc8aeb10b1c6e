// Real-time settings of a process (`realtime:` in host files, `poise run --rt-priority/--cpus/
// --lock-memory`): SCHED_FIFO priority, CPU affinity, locked memory. Applied to the calling
// thread before the DDS participant exists, so every thread Fast DDS creates afterwards inherits
// them. Where the process lacks the permission, each setting that could not be applied gives a
// warning that says how to grant it, and the process keeps running at normal settings.
//
//   realtime:
//     priority: 80        # SCHED_FIFO 1-99 (0 or absent: normal scheduling)
//     cpus: [2, 3]        # CPU affinity (absent: every CPU)
//     lock_memory: true   # mlockall(MCL_CURRENT | MCL_FUTURE): no page faults on the sensor path
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>
#include <vector>

namespace poise::runtime {

struct RealtimeSettings {
  int priority = 0;       ///< SCHED_FIFO priority 1-99; 0 = normal scheduling
  std::vector<int> cpus;  ///< CPU affinity; empty = unchanged
  bool lock_memory = false;
  [[nodiscard]] bool any() const { return priority > 0 || !cpus.empty() || lock_memory; }
};

/// Parses a `realtime:` map; throws ConfigError naming `origin`, the key and the allowed range.
RealtimeSettings parse_realtime(const YAML::Node& node, const std::string& origin);
/// Parses a CPU list "2,3" or "0-3,6" (for --cpus); throws ConfigError.
std::vector<int> parse_cpu_list(const std::string& text, const std::string& origin);

/// Applies the settings to the calling thread (and so to threads it creates later). Returns one
/// warning per setting that could not be applied (why, and how to grant it); empty = all applied.
std::vector<std::string> apply_realtime(const RealtimeSettings& settings);
/// One line describing the settings ("SCHED_FIFO 80, cpus 2,3, memory locked").
std::string describe(const RealtimeSettings& settings);

}  // namespace poise::runtime
