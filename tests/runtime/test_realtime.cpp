// Real-time settings: parsing (clear errors naming the key) and applying them in a child process
// (applied, or a warning that says how to grant the permission; the process goes on).
#include "poise/runtime/component.h"
#include "poise/runtime/realtime.h"

#include <gtest/gtest.h>
#include <sched.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <thread>
#include <string>

namespace poise::runtime {
namespace {

TEST(Realtime, GivenACpuListWhenParsedThenRangesExpandAndBadTextIsRefused) {
  EXPECT_EQ(parse_cpu_list("0-3,6", "--cpus"), (std::vector<int>{0, 1, 2, 3, 6}));
  EXPECT_EQ(parse_cpu_list("2", "--cpus"), (std::vector<int>{2}));
  EXPECT_THROW(parse_cpu_list("a", "--cpus"), ConfigError);
  EXPECT_THROW(parse_cpu_list("3-1", "--cpus"), ConfigError);
  EXPECT_THROW(parse_cpu_list("0-2,1", "--cpus"), ConfigError);  // as the host file: twice is an error
  EXPECT_THROW(parse_cpu_list("", "--cpus"), ConfigError);
  EXPECT_THROW(parse_cpu_list("99999999", "--cpus"), ConfigError);
}

// Child exit codes: which setting neither took effect nor gave the warning that explains it.
constexpr int kAffinityWrong = 10;
constexpr int kPriorityWrong = 11;
constexpr int kMemoryWrong = 12;
constexpr int kThreadNotInherited = 13;

bool memory_locked() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("VmLck:", 0) == 0) {
      return std::stol(line.substr(6)) > 0;
    }
  }
  return false;
}

bool has_warning(const std::vector<std::string>& w, const std::string& text) {
  for (const auto& s : w) {
    if (s.find(text) != std::string::npos) {
      return true;
    }
  }
  return false;
}

int child(int cpu) {
  alarm(10);  // bound: the child only makes a few system calls
  RealtimeSettings r;
  r.priority = 10;
  r.cpus = {cpu};
  r.lock_memory = true;
  const auto warnings = apply_realtime(r);
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) != 0 || CPU_COUNT(&set) != 1 || !CPU_ISSET(cpu, &set)) {
    return kAffinityWrong;  // an allowed cpu always applies
  }
  sched_param sp{};
  const bool fifo = sched_getscheduler(0) == SCHED_FIFO && sched_getparam(0, &sp) == 0 && sp.sched_priority == 10;
  if (!fifo && !has_warning(warnings, "CAP_SYS_NICE")) {
    return kPriorityWrong;
  }
  if (!memory_locked() && !has_warning(warnings, "LimitMEMLOCK")) {
    return kMemoryWrong;
  }
  // a thread created afterwards (as Fast DDS's are) inherits the policy and the affinity
  int inherited = 0;
  std::thread t([&] {
    cpu_set_t ts;
    CPU_ZERO(&ts);
    const bool aff = sched_getaffinity(0, sizeof(ts), &ts) == 0 && CPU_COUNT(&ts) == 1 && CPU_ISSET(cpu, &ts);
    const bool pol = !fifo || sched_getscheduler(0) == SCHED_FIFO;
    inherited = aff && pol ? 1 : 0;
  });
  t.join();
  return inherited == 1 ? 0 : kThreadNotInherited;
}

TEST(Realtime, GivenSettingsWhenAppliedThenEachTakesEffectOrAWarningSaysHowToGrantIt) {
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  ASSERT_EQ(sched_getaffinity(0, sizeof(allowed), &allowed), 0);
  int cpu = 0;
  while (!CPU_ISSET(cpu, &allowed)) {
    ++cpu;
  }
  // in a child, so that the test process keeps its own scheduling
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    _exit(child(cpu));
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "child killed by signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 0) << "10 affinity, 11 priority, 12 memory, 13 not inherited by a new thread";
}

TEST(Realtime, GivenACpuThatDoesNotExistWhenAppliedThenAWarningNamesTheOnlineCpus) {
  RealtimeSettings r;
  r.cpus = {CPU_SETSIZE - 1};
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    alarm(10);
    const auto w = apply_realtime(r);
    _exit(w.size() == 1 && w[0].find("online") != std::string::npos ? 0 : 1);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
}

}  // namespace
}  // namespace poise::runtime
