#include "poise/runtime/realtime.h"

#include "poise/runtime/component.h"

#include "poise/core/yaml_params.h"

#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <set>
#include <sstream>

namespace poise::runtime {
namespace {

constexpr int kMaxFifoPriority = 99;

void check_cpu(int cpu, const std::string& origin) {
  if (cpu < 0 || cpu >= CPU_SETSIZE) {
    throw ConfigError(origin + ": cpu " + std::to_string(cpu) + " is out of range (0-" +
                      std::to_string(CPU_SETSIZE - 1) + ")");
  }
}

std::string join(const std::vector<int>& v) {
  std::string s;
  for (const int x : v) {
    s += (s.empty() ? "" : ",") + std::to_string(x);
  }
  return s;
}

}  // namespace

RealtimeSettings parse_realtime(const YAML::Node& node, const std::string& origin) {
  RealtimeSettings r;
  if (!node || node.IsNull()) {  // absent, or `realtime:` with nothing under it
    return r;
  }
  const std::string where = origin + ": realtime";
  if (!node.IsMap()) {
    throw ConfigError(where + " must be a map (priority, cpus, lock_memory)");
  }
  check_known_keys<ConfigError>(node, {"priority", "cpus", "lock_memory"}, origin, "realtime.");
  try {
    if (node["priority"]) {
      r.priority = node["priority"].as<int>();
      if (r.priority < 0 || r.priority > kMaxFifoPriority) {
        throw ConfigError(where + ".priority must be 1-99 (SCHED_FIFO) or 0 (normal), got " +
                          std::to_string(r.priority));
      }
    }
    if (node["cpus"]) {
      if (!node["cpus"].IsSequence() || node["cpus"].size() == 0) {
        throw ConfigError(where + ".cpus must be a non-empty list of CPU numbers, e.g. [2, 3]");
      }
      std::set<int> seen;
      for (const auto& c : node["cpus"]) {
        const int cpu = c.as<int>();
        check_cpu(cpu, where + ".cpus");
        if (!seen.insert(cpu).second) {
          throw ConfigError(where + ".cpus lists cpu " + std::to_string(cpu) + " twice");
        }
        r.cpus.push_back(cpu);
      }
    }
    if (node["lock_memory"]) {
      r.lock_memory = node["lock_memory"].as<bool>();
    }
  } catch (const YAML::Exception& e) {
    throw ConfigError(where + ": " + e.what());
  }
  return r;
}

std::vector<int> parse_cpu_list(const std::string& text, const std::string& origin) {
  std::vector<int> cpus;
  std::set<int> seen;
  std::stringstream ss(text);
  std::string item;
  auto number = [&](const std::string& s) {
    if (s.empty() || s.find_first_not_of("0123456789") != std::string::npos || s.size() > 5) {
      throw ConfigError(origin + ": '" + text + "' is not a CPU list (e.g. 2,3 or 0-3)");
    }
    return std::stoi(s);
  };
  while (std::getline(ss, item, ',')) {
    const auto dash = item.find('-');
    const int lo = number(item.substr(0, dash));
    const int hi = dash == std::string::npos ? lo : number(item.substr(dash + 1));
    if (hi < lo) {
      throw ConfigError(origin + ": '" + item + "' is an empty CPU range");
    }
    for (int c = lo; c <= hi; ++c) {
      check_cpu(c, origin);
      if (!seen.insert(c).second) {
        throw ConfigError(origin + ": '" + text + "' lists cpu " + std::to_string(c) + " twice");
      }
      cpus.push_back(c);
    }
  }
  if (cpus.empty()) {
    throw ConfigError(origin + ": an empty CPU list");
  }
  return cpus;
}

std::vector<std::string> apply_realtime(const RealtimeSettings& settings) {
  std::vector<std::string> warnings;
  if (!settings.cpus.empty()) {
    cpu_set_t set;
    CPU_ZERO(&set);
    for (const int c : settings.cpus) {
      CPU_SET(c, &set);
    }
    if (sched_setaffinity(0, sizeof(set), &set) != 0) {
      const long online = sysconf(_SC_NPROCESSORS_ONLN);
      warnings.push_back("cpus " + join(settings.cpus) + " not applied: " + std::strerror(errno) +
                         " (this machine has cpus 0-" + std::to_string(online - 1) +
                         " online, and a container or cgroup may allow fewer); running on every cpu allowed");
    }
  }
  if (settings.lock_memory && mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
    warnings.push_back(std::string("memory not locked: ") + std::strerror(errno) +
                       " (grant CAP_IPC_LOCK or raise the limit: LimitMEMLOCK=infinity in the systemd "
                       "unit, `ulimit -l unlimited`); page faults may delay samples");
  }
  if (settings.priority > 0) {
    sched_param sp{};
    sp.sched_priority = settings.priority;
    if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) {
      warnings.push_back("SCHED_FIFO priority " + std::to_string(settings.priority) + " not applied: " +
                         std::strerror(errno) + " (grant CAP_SYS_NICE, or allow it: LimitRTPRIO=" +
                         std::to_string(settings.priority) + " in the systemd unit, `ulimit -r " +
                         std::to_string(settings.priority) +
                         "`, or rtprio in /etc/security/limits.conf); running at normal priority");
    }
  }
  return warnings;
}

std::string describe(const RealtimeSettings& settings) {
  std::string s = settings.priority > 0 ? "SCHED_FIFO " + std::to_string(settings.priority) : "normal scheduling";
  if (!settings.cpus.empty()) {
    s += ", cpus " + join(settings.cpus);
  }
  if (settings.lock_memory) {
    s += ", memory locked";
  }
  return s;
}

}  // namespace poise::runtime
