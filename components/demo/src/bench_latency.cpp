// `poise bench latency`: end-to-end latency of the serial pipeline, next to a bare DDS hop.
//
// Pipeline: this process writes protocol lines on a pseudo-terminal (recording the write instant
// of each seq); a child `poise run` process hosts imu_driver (reading that pty) + parallel_kf; this
// process subscribes to attitude/parallel_kf and measures receive instant - write instant per seq
// (both CLOCK_MONOTONIC). Bare hop: a child publishes AttitudeEstimate samples (the same payload)
// stamped at write; this process measures receive - stamp. Both at each rate, same run.
// CPU: at 1 kHz, imu_driver and parallel_kf each in their own process (`poise imu`,
// `poise parallel-kf`), CPU time from /proc/<pid>/stat over the measurement window.
#include "poise/cli/common.h"
#include "poise/dds/convert.h"
#include "poise/dds/participant.h"
#include "poise/demo/monitor.h"
#include "poise/imu/protocol.h"
#include "poise/imu/pty_link.h"
#include "poise/nodes/imu_node.h"
#include "poise/nodes/reports.h"

#include <poise/msg/estimatesPubSubTypes.h>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>
#include <unordered_map>

extern char** environ;

namespace poise::cli {
namespace {

/// A child `poise` process (the same binary), killed on destruction.
class Process {
 public:
  explicit Process(const std::vector<std::string>& args) {
    std::vector<std::string> argv{self_path()};
    argv.insert(argv.end(), args.begin(), args.end());
    std::vector<char*> c;
    for (auto& a : argv) {
      c.push_back(a.data());
    }
    c.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
    if (posix_spawn(&pid_, c[0], &actions, nullptr, c.data(), environ) != 0) {
      posix_spawn_file_actions_destroy(&actions);
      throw Error("cannot start " + argv[0]);
    }
    posix_spawn_file_actions_destroy(&actions);
  }
  ~Process() {
    ::kill(pid_, SIGINT);
    for (int i = 0; i < 300; ++i) {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;
  /// CPU time (user + system) so far, seconds.
  [[nodiscard]] double cpu_s() const {
    std::ifstream in("/proc/" + std::to_string(pid_) + "/stat");
    std::string content;
    std::getline(in, content);
    const auto close = content.rfind(')');
    if (close == std::string::npos) {
      return 0.0;
    }
    std::istringstream fields(content.substr(close + 2));
    std::string f;
    double utime = 0;
    double stime = 0;
    for (int i = 3; i <= 15 && fields >> f; ++i) {  // fields 14, 15: utime, stime (clock ticks)
      if (i == 14) utime = std::stod(f);
      if (i == 15) stime = std::stod(f);
    }
    return (utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
  }

 private:
  static std::string self_path() {
    char buf[4096];
    const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof buf - 1);
    if (n <= 0) {
      throw Error("cannot find the poise executable (/proc/self/exe)");
    }
    return std::string(buf, static_cast<std::size_t>(n));
  }
  pid_t pid_ = -1;
};

struct Figures {
  double p50 = 0.0, p99 = 0.0, max = 0.0;
  std::size_t n = 0;
};

Figures figures(const std::vector<double>& ms) {
  return {demo::percentile(ms, 50), demo::percentile(ms, 99), demo::percentile(ms, 100), ms.size()};
}

void sleep_until(int64_t t_ns) {
  while (true) {
    const int64_t now = nodes::monotonic_ns();
    if (now >= t_ns) return;
    std::this_thread::sleep_for(std::chrono::nanoseconds(std::min<int64_t>(t_ns - now, 200'000)));
  }
}

std::string line_for(uint32_t seq, int64_t t_ns) {
  imu::RawSample s;
  s.seq = seq;
  s.t_us = static_cast<uint32_t>(static_cast<uint64_t>(t_ns / 1000) & 0xFFFFFFFFULL);
  s.accel_mps2 = {0.02, -0.01, 9.80665};
  s.gyro_rps = {0.001, -0.002, 0.0005};
  s.mag_ut = {0.0, 25.0, -43.3};
  return imu::format_imu_line(s);
}

struct BenchOptions {
  int domain = 0;
  double seconds = 10.0;
  std::vector<double> rates{200.0, 1000.0};
  // hidden: the bare-hop publisher role
  bool hop_publisher = false;
  double hop_rate = 0.0;
  double hop_seconds = 0.0;
};

/// Pipeline latency at `rate` for `seconds` (after 2 s of warm-up).
Figures pipeline_latency(const BenchOptions& o, double rate, double* cpu_percent) {
  const std::string link = "/tmp/poise-bench-imu-" + std::to_string(::getpid());
  imu::PtyLink pty(link);
  const std::string host = "/tmp/poise-bench-" + std::to_string(::getpid()) + ".yaml";
  std::ofstream(host) << "components:\n  - {type: imu_driver, name: imu0, params: {port: " << link
                      << "}}\n  - {type: parallel_kf, params: {diagnostics_every: 1}}\n";
  dds::Participant participant({o.domain, "", "", "bench_latency"});
  std::mutex mutex;
  std::unordered_map<uint32_t, int64_t> written;
  std::vector<double> latencies;
  bool measuring = false;
  dds::Reader<msg::AttitudeEstimatePubSubType> reader(
      participant, "attitude/parallel_kf", dds::QosKind::kEstimate,
      [&](const msg::AttitudeEstimate& m, const auto&) {
        const int64_t now = nodes::monotonic_ns();
        std::lock_guard<std::mutex> lock(mutex);
        const auto it = written.find(m.header().seq());
        if (measuring && it != written.end()) {
          latencies.push_back(static_cast<double>(now - it->second) * 1e-6);
        }
      });
  Process child({"run", host, "--domain", std::to_string(o.domain), "--quiet"});
  if (!reader.wait_for_writers(1, std::chrono::seconds(20))) {
    throw Error("the pipeline process did not come up (no attitude/parallel_kf writer in 20 s)");
  }
  const auto period = static_cast<int64_t>(1e9 / rate);
  const int64_t start = nodes::monotonic_ns();
  const auto warmup = static_cast<int64_t>(2.0 * rate);
  const auto total = warmup + static_cast<int64_t>(o.seconds * rate);
  double cpu0 = 0.0;
  int64_t t_measure = 0;
  for (int64_t k = 0; k < total && !stop_requested(); ++k) {
    const int64_t t = start + k * period;
    sleep_until(t);
    if (k == warmup) {
      std::lock_guard<std::mutex> lock(mutex);
      measuring = true;
      cpu0 = child.cpu_s();
      t_measure = nodes::monotonic_ns();
    }
    const auto seq = static_cast<uint32_t>(k);
    const std::string line = line_for(seq, t - start);
    {
      std::lock_guard<std::mutex> lock(mutex);
      written[seq] = nodes::monotonic_ns();
    }
    pty.write(line);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  *cpu_percent = 100.0 * (child.cpu_s() - cpu0) /
                 (static_cast<double>(nodes::monotonic_ns() - t_measure) * 1e-9);
  ::unlink(host.c_str());
  std::lock_guard<std::mutex> lock(mutex);
  return figures(latencies);
}

/// Bare DDS hop at `rate`: a child publishes stamped AttitudeEstimates, this process receives.
Figures bare_hop(const BenchOptions& o, double rate) {
  dds::Participant participant({o.domain, "", "", "bench_hop"});
  std::mutex mutex;
  std::vector<double> latencies;
  const auto warmup = static_cast<uint32_t>(2.0 * rate);
  dds::Reader<msg::AttitudeEstimatePubSubType> reader(
      participant, "bench/hop", dds::QosKind::kEstimate, [&](const msg::AttitudeEstimate& m, const auto&) {
        const int64_t now = nodes::monotonic_ns();
        if (m.header().seq() >= warmup) {
          std::lock_guard<std::mutex> lock(mutex);
          latencies.push_back(static_cast<double>(now - m.header().stamp_ns()) * 1e-6);
        }
      });
  Process child({"bench", "latency", "--hop-publisher", "--domain", std::to_string(o.domain), "--hop-rate",
                 std::to_string(rate), "--hop-seconds", std::to_string(o.seconds + 2.0)});
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.seconds + 25.0);
  while (std::chrono::steady_clock::now() < deadline && !stop_requested()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    std::lock_guard<std::mutex> lock(mutex);
    if (latencies.size() >= static_cast<std::size_t>(o.seconds * rate * 0.999)) {
      break;
    }
  }
  std::lock_guard<std::mutex> lock(mutex);
  return figures(latencies);
}

void run_hop_publisher(const BenchOptions& o) {
  install_stop_handlers();
  dds::Participant participant({o.domain, "", "", "bench_hop_publisher"});
  dds::Writer<msg::AttitudeEstimatePubSubType> writer(participant, "bench/hop", dds::QosKind::kEstimate);
  writer.wait_for_readers(1, std::chrono::seconds(20));
  nodes::AttitudeReport r;
  const auto period = static_cast<int64_t>(1e9 / o.hop_rate);
  const int64_t start = nodes::monotonic_ns();
  const auto total = static_cast<int64_t>(o.hop_seconds * o.hop_rate);
  for (int64_t k = 0; k < total && !stop_requested(); ++k) {
    sleep_until(start + k * period);
    r.seq = static_cast<uint32_t>(k);
    r.stamp_ns = nodes::monotonic_ns();
    writer.write(nodes::to_attitude_msg(r, "bench", "parallel_kf"));
  }
}

/// CPU % of each component in its own process at `rate`.
std::pair<double, double> component_cpu(const BenchOptions& o, double rate) {
  const std::string link = "/tmp/poise-bench-cpu-" + std::to_string(::getpid());
  imu::PtyLink pty(link);
  dds::Participant participant({o.domain, "", "", "bench_cpu"});
  std::atomic<uint64_t> received{0};
  dds::Reader<msg::AttitudeEstimatePubSubType> reader(
      participant, "attitude/parallel_kf", dds::QosKind::kEstimate,
      [&](const auto&, const auto&) { received.fetch_add(1); });
  Process driver({"imu", "--port", link, "--domain", std::to_string(o.domain)});
  Process filter({"parallel-kf", "--domain", std::to_string(o.domain), "--quiet"});
  reader.wait_for_writers(1, std::chrono::seconds(20));
  const auto period = static_cast<int64_t>(1e9 / rate);
  const int64_t start = nodes::monotonic_ns();
  const auto warmup = static_cast<int64_t>(2.0 * rate);
  const auto total = warmup + static_cast<int64_t>(o.seconds * rate);
  double d0 = 0, f0 = 0;
  int64_t t0 = 0;
  for (int64_t k = 0; k < total && !stop_requested(); ++k) {
    sleep_until(start + k * period);
    if (k == warmup) {
      d0 = driver.cpu_s();
      f0 = filter.cpu_s();
      t0 = nodes::monotonic_ns();
    }
    pty.write(line_for(static_cast<uint32_t>(k), start + k * period - start));
  }
  const double wall = static_cast<double>(nodes::monotonic_ns() - t0) * 1e-9;
  if (received.load() == 0) {
    throw Error("the two-process pipeline produced no estimate");
  }
  return {100.0 * (driver.cpu_s() - d0) / wall, 100.0 * (filter.cpu_s() - f0) / wall};
}

void run_bench(const BenchOptions& o) {
  if (o.hop_publisher) {
    run_hop_publisher(o);
    return;
  }
  install_stop_handlers();
  std::printf("poise bench latency: line written on the pty -> attitude estimate received in another "
              "process (imu_driver + parallel_kf in one `poise run` process), %.0f s per rate, next to a "
              "bare Fast DDS hop of the same payload (AttitudeEstimate). Times in ms.\n\n", o.seconds);
  std::printf("%8s | %28s | %28s | %9s | %8s\n", "rate Hz", "pipeline p50 / p99 / max", "bare hop p50 / p99 / max",
              "p99 ratio", "host CPU");
  for (double rate : o.rates) {
    double cpu = 0.0;
    const Figures p = pipeline_latency(o, rate, &cpu);
    const Figures h = bare_hop(o, rate);
    std::printf("%8.0f | %8.3f / %7.3f / %7.3f | %8.3f / %7.3f / %7.3f | %9.2f | %6.1f %%\n", rate, p.p50,
                p.p99, p.max, h.p50, h.p99, h.max, p.p99 / h.p99, cpu);
    std::printf("%8s | %28zu | %28zu |\n", "samples", p.n, h.n);
    std::fflush(stdout);
  }
  const auto [driver_cpu, filter_cpu] = component_cpu(o, 1000.0);
  std::printf("\nCPU at 1 kHz, each component in its own process (%% of one core): imu_driver %.1f %%, "
              "parallel_kf %.1f %%\n", driver_cpu, filter_cpu);
}

}  // namespace

void register_bench_latency(CLI::App& app) {
  auto o = std::make_shared<BenchOptions>();
  CLI::App* bench = subcommand_group(app, "bench", "Benchmarks that print figures");
  CLI::App* cmd = bench->add_subcommand(
      "latency", "Pipeline latency (pty line -> estimate in another process) vs a bare DDS hop; CPU per component");
  add_domain_option(cmd, &o->domain);
  cmd->add_option("--seconds", o->seconds, "Measurement time per rate, s")->check(CLI::Range(1.0, 600.0))->capture_default_str();
  cmd->add_option("--rates", o->rates, "IMU rates, Hz")->check(CLI::Range(1.0, 5000.0));
  cmd->add_flag("--hop-publisher", o->hop_publisher)->group("");  // internal: the bare-hop peer
  cmd->add_option("--hop-rate", o->hop_rate)->group("");
  cmd->add_option("--hop-seconds", o->hop_seconds)->group("");
  cmd->callback([o] { run_bench(*o); });
}

}  // namespace poise::cli
