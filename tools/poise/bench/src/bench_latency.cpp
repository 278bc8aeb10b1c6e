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
#include "poise/nodes/imu_estimator_node.h"
#include "poise/nodes/reports.h"
#include "poise/runtime/realtime.h"

#include <poise/msg/estimatesPubSubTypes.h>

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <signal.h>
#include <sched.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <time.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstdint>
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
    // Children start at normal scheduling even when this process runs at SCHED_FIFO (--realtime):
    // a child is real-time only when its own options say so.
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    sched_param normal{};
    posix_spawnattr_setschedpolicy(&attr, SCHED_OTHER);
    posix_spawnattr_setschedparam(&attr, &normal);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSCHEDULER);
    const int rc = posix_spawn(&pid_, c[0], &actions, &attr, c.data(), environ);
    posix_spawnattr_destroy(&attr);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) {
      throw Error("cannot start " + argv[0]);
    }
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
  void signal(int sig) const { ::kill(pid_, sig); }
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

/// Sleeps until CLOCK_MONOTONIC reaches t_ns: one absolute-deadline wake-up per call (no polling
/// wake-ups competing with the measured threads), in slices of at most 100 ms for Ctrl-C.
void sleep_until(int64_t t_ns) {
  while (!stop_requested()) {
    const int64_t now = nodes::monotonic_ns();
    if (now >= t_ns) return;
    const int64_t until = std::min<int64_t>(t_ns, now + 100'000'000);
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(until / 1'000'000'000);
    ts.tv_nsec = static_cast<long>(until % 1'000'000'000);
    ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
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
  std::string profile;  // DDS participant profile; given, it reaches the child processes by $POISE_DDS_PROFILE
  double seconds = 10.0;
  double window_s = 1.0;
  int diagnostics_every = 1;
  std::vector<double> rates{200.0, 1000.0};
  int load_threads = 0;   ///< competing busy threads for the whole run (normal priority, any core)
  bool realtime = false;  ///< each rate measured twice: the pipeline at normal and at real-time settings
  int rt_priority = 80;
  // hidden: the bare-hop publisher role
  bool hop_publisher = false;
  double hop_rate = 0.0;
  double hop_seconds = 0.0;
};

/// Latencies (ms) received in this process, recorded only while `recording`.
class Collector {
 public:
  void add(double ms) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (recording_) {
      latencies_.push_back(ms);
    }
  }
  void set_recording(bool on) {
    std::lock_guard<std::mutex> lock(mutex_);
    recording_ = on;
  }
  [[nodiscard]] std::vector<double> latencies() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return latencies_;
  }

 private:
  mutable std::mutex mutex_;
  bool recording_ = false;
  std::vector<double> latencies_;
};

struct RateResult {
  Figures pty;  ///< line written -> read by another thread of this process (the kernel's pty hop)
  Figures pipeline;
  Figures hop;
  double host_cpu_percent = 0.0;
  std::vector<double> round_ratios;  ///< p99 ratio of each round (pipeline window vs hop window)
};

/// The pty hop alone: a thread of this process reads a second pty (raw mode, poll + read, as the
/// driver does) and records, per line, read instant - write instant.
class PtyEcho {
 public:
  PtyEcho(const std::string& link, Collector& out) : link_(link), out_(out) {
    fd_ = ::open(link_.link_path().c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0) {
      throw Error("cannot open " + link_.link_path());
    }
    termios tio{};
    ::tcgetattr(fd_, &tio);
    ::cfmakeraw(&tio);
    ::tcsetattr(fd_, TCSANOW, &tio);
    thread_ = std::thread([this] { loop(); });
  }
  ~PtyEcho() {
    stop_.store(true);
    thread_.join();
    ::close(fd_);
  }
  PtyEcho(const PtyEcho&) = delete;
  PtyEcho& operator=(const PtyEcho&) = delete;
  /// Writes one line, remembering the instant.
  void write(const std::string& line) {
    sent_ns_.store(nodes::monotonic_ns());
    link_.write(line);
  }

 private:
  void loop() {
    char buf[4096];
    while (!stop_.load()) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) {
        continue;
      }
      const ssize_t n = ::read(fd_, buf, sizeof buf);
      if (n > 0 && buf[n - 1] == '\n') {
        out_.add(static_cast<double>(nodes::monotonic_ns() - sent_ns_.load()) * 1e-6);
      }
    }
  }
  imu::PtyLink link_;
  Collector& out_;
  int fd_ = -1;
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> sent_ns_{0};
  std::thread thread_;
};

/// Pipeline and bare hop at `rate`, measured in alternating windows of `window_s` (pipeline, then
/// hop, repeated for `seconds` of each) so both see the same machine conditions; both children stay
/// up, idle outside their windows. Pipeline: this process writes protocol lines on a pty read by
/// the `poise run` child (imu_driver + parallel_kf) and times write -> attitude/parallel_kf
/// received. Hop: the `--hop-publisher` child publishes stamped AttitudeEstimates while resumed
/// (SIGUSR1 toggles it) and this process times stamp -> received.
// not split: one measurement's lifecycle (children started, alternating windows, children stopped)
// whose parts share the child processes and the timing buffers.
RateResult measure_rate(const BenchOptions& o, double rate, bool pipeline_realtime) {
  const std::string link = "/tmp/poise-bench-imu-" + std::to_string(::getpid());
  imu::PtyLink pty(link);
  const std::string host = "/tmp/poise-bench-" + std::to_string(::getpid()) + ".yaml";
  std::ofstream(host) << "components:\n  - {type: imu_driver, name: imu0, params: {port: " << link
                      << "}}\n  - {type: parallel_kf, params: {diagnostics_every: " << o.diagnostics_every
                      << "}}\n";
  dds::Participant participant({o.domain, "", "", "bench_latency"});
  std::mutex mutex;
  std::unordered_map<uint32_t, int64_t> written;
  Collector pipeline;
  Collector hop;
  Collector pty_hop;
  PtyEcho echo("/tmp/poise-bench-echo-" + std::to_string(::getpid()), pty_hop);
  dds::Reader<msg::AttitudeEstimatePubSubType> reader(
      participant, "attitude/parallel_kf", dds::QosKind::kEstimate,
      [&](const msg::AttitudeEstimate& m, const auto&) {
        const int64_t now = nodes::monotonic_ns();
        int64_t sent = 0;
        {
          std::lock_guard<std::mutex> lock(mutex);
          const auto it = written.find(m.header().seq());
          if (it == written.end()) {
            return;
          }
          sent = it->second;
          written.erase(it);
        }
        pipeline.add(static_cast<double>(now - sent) * 1e-6);
      });
  dds::Reader<msg::AttitudeEstimatePubSubType> hop_reader(
      participant, "bench/hop", dds::QosKind::kEstimate, [&](const msg::AttitudeEstimate& m, const auto&) {
        hop.add(static_cast<double>(nodes::monotonic_ns() - m.header().stamp_ns()) * 1e-6);
      });
  std::vector<std::string> run_args{"run", host, "--domain", std::to_string(o.domain), "--quiet"};
  if (pipeline_realtime) {  // the host's real-time settings, as `poise run` applies them
    run_args.insert(run_args.end(), {"--rt-priority", std::to_string(o.rt_priority), "--lock-memory"});
  }
  Process child(run_args);
  Process hop_child({"bench", "latency", "--hop-publisher", "--domain", std::to_string(o.domain), "--hop-rate",
                     std::to_string(rate)});
  if (!reader.wait_for_writers(1, std::chrono::seconds(20))) {
    ::unlink(host.c_str());
    throw Error("the pipeline process did not come up (no attitude/parallel_kf writer in 20 s)");
  }
  if (!hop_reader.wait_for_writers(1, std::chrono::seconds(20))) {
    ::unlink(host.c_str());
    throw Error("the bare-hop publisher did not come up (no bench/hop writer in 20 s)");
  }
  const auto period = static_cast<int64_t>(1e9 / rate);
  const int64_t t0 = nodes::monotonic_ns();
  uint32_t seq = 0;
  // Writes lines for `seconds` at `rate` on the pipeline's pty (or, with `to_echo`, the echo pty).
  auto write_lines = [&](double seconds, bool to_echo = false) {
    const int64_t start = nodes::monotonic_ns();
    const auto n = static_cast<int64_t>(seconds * rate);
    for (int64_t k = 0; k < n && !stop_requested(); ++k) {
      const int64_t t = start + k * period;
      sleep_until(t);
      const std::string line = line_for(seq, t - t0);
      if (to_echo) {
        echo.write(line);
        continue;
      }
      {
        std::lock_guard<std::mutex> lock(mutex);
        written[seq] = nodes::monotonic_ns();
      }
      pty.write(line);
      ++seq;
    }
  };
  auto hop_window = [&](double seconds) {
    hop_child.signal(SIGUSR1);  // resume
    sleep_until(nodes::monotonic_ns() + static_cast<int64_t>(seconds * 1e9));
    hop_child.signal(SIGUSR1);  // pause
  };
  auto settle = [] { std::this_thread::sleep_for(std::chrono::milliseconds(100)); };
  // Warm-up (not recorded): 2 s of each.
  write_lines(2.0);
  settle();
  hop_window(2.0);
  settle();

  RateResult result;
  const int rounds = std::max(1, static_cast<int>(std::lround(o.seconds / o.window_s)));
  const double cpu0 = child.cpu_s();
  double pipeline_wall = 0.0;
  for (int r = 0; r < rounds && !stop_requested(); ++r) {
    const size_t p0 = pipeline.latencies().size();
    const size_t h0 = hop.latencies().size();
    pipeline.set_recording(true);
    const int64_t w0 = nodes::monotonic_ns();
    write_lines(o.window_s);
    pipeline_wall += static_cast<double>(nodes::monotonic_ns() - w0) * 1e-9;
    settle();
    pipeline.set_recording(false);
    hop.set_recording(true);
    hop_window(o.window_s);
    settle();
    hop.set_recording(false);
    pty_hop.set_recording(true);
    write_lines(o.window_s / 2.0, true);
    settle();
    pty_hop.set_recording(false);
    const auto pl = pipeline.latencies();
    const auto hl = hop.latencies();
    const std::vector<double> pr(pl.begin() + static_cast<std::ptrdiff_t>(p0), pl.end());
    const std::vector<double> hr(hl.begin() + static_cast<std::ptrdiff_t>(h0), hl.end());
    if (!pr.empty() && !hr.empty()) {
      result.round_ratios.push_back(demo::percentile(pr, 99) / demo::percentile(hr, 99));
    }
  }
  // The child idles in the hop windows: its CPU is charged to the pipeline windows' wall time.
  result.host_cpu_percent = pipeline_wall > 0.0 ? 100.0 * (child.cpu_s() - cpu0) / pipeline_wall : 0.0;
  ::unlink(host.c_str());
  result.pipeline = figures(pipeline.latencies());
  result.pty = figures(pty_hop.latencies());
  result.hop = figures(hop.latencies());
  return result;
}

void run_hop_publisher(const BenchOptions& o) {
  install_stop_handlers();
  static std::atomic<bool> paused{true};
  struct sigaction sa {};
  sa.sa_handler = [](int) { paused.store(!paused.load()); };
  sigemptyset(&sa.sa_mask);
  ::sigaction(SIGUSR1, &sa, nullptr);
  dds::Participant participant({o.domain, "", "", "bench_hop_publisher"});
  dds::Writer<msg::AttitudeEstimatePubSubType> writer(participant, "bench/hop", dds::QosKind::kEstimate);
  writer.wait_for_readers(1, std::chrono::seconds(20));
  nodes::AttitudeReport r;
  const auto period = static_cast<int64_t>(1e9 / o.hop_rate);
  int64_t next = nodes::monotonic_ns();
  uint32_t seq = 0;
  const int64_t end = o.hop_seconds > 0.0 ? next + static_cast<int64_t>(o.hop_seconds * 1e9) : INT64_MAX;
  while (!stop_requested() && nodes::monotonic_ns() < end) {
    next += period;
    sleep_until(next);
    if (paused.load()) {
      continue;
    }
    r.seq = seq++;
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
  // Competing load: busy threads at normal priority on every core for the whole run.
  std::atomic<bool> load_stop{false};
  std::vector<std::thread> load;
  for (int i = 0; i < o.load_threads; ++i) {
    load.emplace_back([&load_stop] {
      volatile uint64_t spin = 0;
      while (!load_stop.load(std::memory_order_relaxed)) {
        spin = spin + 1;
      }
    });
  }
  struct StopLoad {
    std::atomic<bool>& stop;
    std::vector<std::thread>& threads;
    ~StopLoad() {
      stop = true;
      for (auto& t : threads) {
        t.join();
      }
    }
  } stop_load{load_stop, load};
  if (o.realtime) {
    // the measuring side (this process's DDS threads, created after this) at real-time priority in
    // both rows, so that only the pipeline's settings differ between them
    runtime::RealtimeSettings rt;
    rt.priority = o.rt_priority;
    for (const auto& w : runtime::apply_realtime(rt)) {
      std::printf("warning: %s\n", w.c_str());
    }
  }
  std::printf("load: %d busy thread(s) at normal priority%s\n", o.load_threads,
              o.realtime ? "; each rate measured with the pipeline at normal scheduling and at SCHED_FIFO "
                           "(`poise run --rt-priority P --lock-memory`)" : "");
  std::printf("poise bench latency: line written on the pty -> attitude estimate received in another "
              "process (imu_driver + parallel_kf in one `poise run` process), next to a bare Fast DDS hop "
              "of the same payload (AttitudeEstimate), measured in alternating %.1f s windows for %.0f s "
              "each. Times in ms.\n\n", o.window_s, o.seconds);
  std::printf("%8s | %28s | %28s | %9s | %17s | %8s\n", "rate Hz", "pipeline p50 / p99 / max",
              "bare hop p50 / p99 / max", "p99 ratio", "rounds min/median", "host CPU");
  std::vector<std::pair<double, bool>> runs;
  for (double rate : o.rates) {
    runs.emplace_back(rate, false);
    if (o.realtime) {
      runs.emplace_back(rate, true);
    }
  }
  for (const auto& [rate, rt] : runs) {
    if (o.realtime) {
      std::printf("%s\n", rt ? "pipeline: SCHED_FIFO, memory locked" : "pipeline: normal scheduling");
    }
    const RateResult r = measure_rate(o, rate, rt);
    std::vector<double> ratios = r.round_ratios;
    std::sort(ratios.begin(), ratios.end());
    const double rmin = ratios.empty() ? 0.0 : ratios.front();
    const double rmed = ratios.empty() ? 0.0 : demo::percentile(ratios, 50);
    std::printf("%8.0f | %8.3f / %7.3f / %7.3f | %8.3f / %7.3f / %7.3f | %9.2f | %7.2f / %7.2f | %6.1f %%\n", rate,
                r.pipeline.p50, r.pipeline.p99, r.pipeline.max, r.hop.p50, r.hop.p99, r.hop.max,
                r.hop.p99 > 0.0 ? r.pipeline.p99 / r.hop.p99 : 0.0, rmin, rmed, r.host_cpu_percent);
    std::printf("%8s | %28zu | %28zu |\n", "samples", r.pipeline.n, r.hop.n);
    std::printf("%8s | %8.3f / %7.3f / %7.3f | the pty hop alone (line written -> read by a thread here), %zu lines\n",
                "pty only", r.pty.p50, r.pty.p99, r.pty.max, r.pty.n);
    std::fflush(stdout);
    if (r.pipeline.n == 0 || r.hop.n == 0) {
      throw Error("no samples received at " + std::to_string(rate) + " Hz");
    }
  }
  const auto [driver_cpu, filter_cpu] = component_cpu(o, 1000.0);
  std::printf("\nCPU at 1 kHz, each component in its own process (%% of one core): imu_driver %.1f %%, "
              "parallel_kf %.1f %%\n", driver_cpu, filter_cpu);
}

}  // namespace

void register_bench_latency(CLI::App& app) {
  auto o = std::make_shared<BenchOptions>();
  CLI::App* bench = subcommand_group(app, "bench", "Benchmarks (figures printed, not asserted)");
  CLI::App* cmd = bench->add_subcommand(
      "latency", "Pipeline latency (pty line -> estimate in another process) vs a bare DDS hop; CPU per component");
  add_domain_option(cmd, &o->domain);
  add_dds_profile_option(cmd, &o->profile);
  cmd->add_option("--duration", o->seconds, "Measurement time per rate and path, s")->check(CLI::Range(1.0, 600.0))->capture_default_str();
  add_deprecated_alias(cmd, "--seconds", "--duration", &o->seconds)->check(CLI::Range(1.0, 600.0));
  cmd->add_option("--diagnostics-every", o->diagnostics_every,
                  "parallel_kf publishes FilterDiagnostics every N samples (1 = input rate, this bench's default; "
                  "0 = the node's diagnostics_rate_hz, 5 Hz)")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  cmd->add_option("--window", o->window_s, "Length of each alternating pipeline / bare-hop window, s")
      ->check(CLI::Range(0.2, 60.0))
      ->capture_default_str();
  cmd->add_option("--rates", o->rates, "IMU rates, Hz")->check(CLI::Range(1.0, 5000.0));
  cmd->add_option("--load", o->load_threads, "Competing busy threads (normal priority, any core) for the whole run")
      ->check(CLI::Range(0, 256))
      ->capture_default_str();
  cmd->add_flag("--realtime", o->realtime,
                "Measure each rate twice: the pipeline at normal scheduling and at SCHED_FIFO with memory locked");
  cmd->add_option("--rt-priority", o->rt_priority, "SCHED_FIFO priority for --realtime")
      ->check(CLI::Range(1, 99))
      ->capture_default_str();
  cmd->add_flag("--hop-publisher", o->hop_publisher)->group("");  // internal: the bare-hop peer
  cmd->add_option("--hop-rate", o->hop_rate)->group("");
  cmd->add_option("--hop-seconds", o->hop_seconds)->group("");
  cmd->callback([o] {
    if (!o->profile.empty()) {  // this process's participants and every child's
      ::setenv("POISE_DDS_PROFILE", o->profile.c_str(), 1);
    }
    run_bench(*o);
  });
}

}  // namespace poise::cli
