// `poise imu`, `poise sim-imu`, `poise calibrate imu`, `poise bench imu` (issue 6).
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "poise/cli/common.h"
#include "poise/eval/broad.h"
#include "poise/imu/config.h"
#include "poise/imu/driver.h"
#include "poise/imu/faults.h"
#include "poise/imu/imu_driver_node.h"
#include "poise/imu/mag_calibration.h"
#include "poise/imu/pty_link.h"
#include "poise/imu/serial_port.h"
#include "poise/runtime/host.h"
#include "poise/runtime/shipped.h"
#include "poise/imu/sensor_info.h"
#include "poise/sim/sample_delay.h"
#include "poise/sim/sensor_simulator.h"

namespace poise::cli {

// Defined in imu_cli_tools.cpp.
void add_calibrate_imu(CLI::App& app);
void add_bench_imu(CLI::App& app);

namespace {

// ---------------------------------------------------------------- poise imu
struct ImuOptions {
  std::string port;
  int baud = 0;
  std::string config;
  std::string name = "imu0";
  std::string profile;
  int domain = 0;
  double duration_s = 0;
  double status_period_s = 2.0;
  bool quiet = false;
  int rt_priority = 0;  // SCHED_FIFO for every thread (the serial reader included); 0 = normal
  bool lock_memory = false;
};

void run_imu(const ImuOptions& o) {
  runtime::RealtimeSettings rt;
  rt.priority = o.rt_priority;
  rt.lock_memory = o.lock_memory;
  if (rt.any()) {  // before the participant and the reader thread exist: they inherit it
    for (const auto& w : runtime::apply_realtime(rt)) std::fprintf(stderr, "poise imu: warning: %s\n", w.c_str());
  }
  runtime::HostSpec spec;
  spec.participant_profile = o.profile;
  runtime::ComponentSpec c;
  c.type = "imu_driver";
  c.name = o.name;
  c.origin = "poise imu";
  c.params = YAML::Node(YAML::NodeType::Map);
  c.params["port"] = o.port;
  if (o.baud != 0) c.params["baud"] = o.baud;
  if (!o.config.empty()) c.params["config_file"] = o.config;
  spec.components.push_back(c);
  install_stop_handlers();
  std::unique_ptr<runtime::Host> host;
  try {
    host = std::make_unique<runtime::Host>(spec, o.domain);
  } catch (const runtime::ConfigError& e) {
    throw Error(e.what());
  }
  host->start();
  if (!o.quiet) {
    std::fprintf(stderr, "poise imu: reading %s, publishing ImuSample on 'imu' (domain %d); Ctrl-C stops\n",
                 o.port.c_str(), o.domain);
  }
  const auto start = std::chrono::steady_clock::now();
  auto next_status = start + std::chrono::duration<double>(o.status_period_s);
  while (!stop_requested()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const auto now = std::chrono::steady_clock::now();
    if (o.duration_s > 0 && std::chrono::duration<double>(now - start).count() >= o.duration_s) break;
    if (!o.quiet && now >= next_status) {
      for (const auto& line : host->status()) std::fprintf(stderr, "  %s\n", line.c_str());
      next_status += std::chrono::duration<double>(o.status_period_s);
    }
  }
  host->stop();
  // The final counts, whatever stopped it (SIGINT, SIGTERM, --duration), --quiet or not: what was
  // read, published and rejected by reason (stdout; the driver's status() after stop()).
  for (const auto& line : host->status()) std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  if (!o.quiet) std::fprintf(stderr, "poise imu: stopped\n");
}

// ---------------------------------------------------------------- poise sim-imu
struct SimImuOptions {
  std::string link;
  std::string source = "trajectory";
  std::string scenario = "demo";
  double rate_hz = 0;  // 0: 200 Hz for trajectories, the file's rate for BROAD
  std::string faults;
  std::string format = "si";
  double duration_s = 0;
  uint64_t count = 0;
  uint64_t seed = 1;
  double drift_ppm = 0;
  uint32_t t_start_us = 0;
  double speed = 1.0;
  std::vector<double> mag_hard_iron;  // 3 values, uT
  std::vector<double> mag_soft_iron;  // 9 values, row-major
  bool loop = false;
  bool quiet = false;
  int dlpf = -1;  // MPU6050 DLPF_CFG to model (its datasheet delay + the $INF line); -1: none
  bool sensor_info = true;  // without --dlpf, the trajectory says its delay (0); false: says nothing
};

/// A still start then tumbling through every orientation, no magnets: for `poise calibrate imu`.
sim::SimConfig calibration_scenario(double rate_hz, uint64_t seed) {
  sim::SimConfig c = sim::make_scenario("static_magnet", rate_hz, seed);
  c.name = "calibration";
  c.magnets.clear();
  sim::MotionSegment rest;
  rest.name = "static";
  rest.duration_s = 8.0;
  sim::MotionSegment tumble;
  tumble.name = "tumble";
  tumble.duration_s = 120.0;
  tumble.rotation_amplitude_rps = 2.5;
  tumble.rotation_freq_hz = 0.2;
  tumble.level_gain_per_s = 0.0;
  c.segments = {rest, tumble};
  c.duration_s = 0;
  return c;
}

/// Produces ImuSamples for sim-imu from the simulator or a BROAD file.
class SimSource {
 public:
  SimSource(const SimImuOptions& o, double* rate_hz) {
    if (o.source == "trajectory") {
      const double rate = o.rate_hz > 0 ? o.rate_hz : 200.0;
      if (o.scenario == "calibration") {
        config_ = calibration_scenario(rate, o.seed);
      } else {
        try {
          config_ = sim::make_scenario(o.scenario, rate, o.seed);
        } catch (const std::invalid_argument& e) {
          std::string names = "calibration";
          for (const auto& n : sim::scenario_names()) names += ", " + n;
          throw Error("--scenario " + o.scenario + ": unknown (use one of " + names + ")");
        }
      }
      config_.duration_s = 0;  // endless: sim-imu stops on --duration/--count/Ctrl-C
      sim_ = std::make_unique<sim::SensorSimulator>(config_);
      *rate_hz = rate;
    } else if (o.source.rfind("broad:", 0) == 0) {
      const std::string path = o.source.substr(6);
      try {
        trial_ = std::make_unique<eval::BroadTrial>(eval::load_broad(path));
      } catch (const std::exception& e) {
        throw Error(std::string("--source ") + o.source + ": " + e.what());
      }
      if (trial_->size() == 0) throw Error("--source " + o.source + ": the file has no samples");
      *rate_hz = o.rate_hz > 0 ? o.rate_hz : trial_->rate_hz;
      loop_ = o.loop;
    } else {
      throw Error("--source must be 'trajectory' or 'broad:FILE', got '" + o.source + "'",
                  kUsageExitCode);
    }
  }
  /// The board was reset: start the trajectory / recording from the beginning.
  void restart() {
    if (sim_) sim_ = std::make_unique<sim::SensorSimulator>(config_);
    k_ = 0;
  }
  /// False when a BROAD file is exhausted (and --loop is off).
  bool next(ImuSample* s) {
    if (sim_) {
      *s = sim_->next().imu;
      return true;
    }
    if (k_ >= trial_->size()) {
      if (!loop_) return false;
      k_ = 0;
    }
    *s = trial_->sample(k_++);
    return true;
  }

 private:
  sim::SimConfig config_;
  std::unique_ptr<sim::SensorSimulator> sim_;
  std::unique_ptr<eval::BroadTrial> trial_;
  std::size_t k_ = 0;
  bool loop_ = false;
};

int32_t to_counts(double v, double lsb_per_unit) {
  const double c = std::round(v * lsb_per_unit);
  return static_cast<int32_t>(std::clamp(c, -32768.0, 32767.0));
}

std::string make_line(const ImuSample& s, uint32_t seq, uint32_t t_us, bool raw_format) {
  if (!raw_format) {
    imu::RawSample r;
    r.seq = seq;
    r.t_us = t_us;
    r.accel_mps2 = s.accel_mps2;
    r.gyro_rps = s.gyro_rps;
    r.mag_ut = s.mag_ut;
    r.has_mag = s.has_mag;
    r.has_pressure = s.has_pressure;
    r.pressure_pa = s.pressure_pa;
    r.has_temperature = s.has_temperature;
    r.temperature_c = s.temperature_c;
    return imu::format_imu_line(r);
  }
  const imu::RawScale k;
  constexpr double kPi = 3.14159265358979323846;
  imu::RawCounts c;
  c.seq = seq;
  c.t_us = t_us;
  for (int i = 0; i < 3; ++i) {
    const auto u = static_cast<std::size_t>(i);
    c.accel[u] = to_counts(s.accel_mps2(i), k.accel_lsb_per_g / k.g_mps2);
    c.gyro[u] = to_counts(s.gyro_rps(i), k.gyro_lsb_per_dps * 180.0 / kPi);
    c.mag[u] = to_counts(s.mag_ut(i), k.mag_lsb_per_gauss / 100.0);
  }
  c.has_mag = s.has_mag;
  c.has_pressure = s.has_pressure;
  c.pressure_pa = static_cast<int32_t>(std::lround(s.pressure_pa));
  c.has_temperature = s.has_temperature;
  c.temperature = to_counts(s.temperature_c - k.temp_offset_c, k.temp_lsb_per_c);
  return imu::format_raw_line(c);
}

void sleep_until_ns(int64_t t_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / 1000000000LL);
  ts.tv_nsec = static_cast<long>(t_ns % 1000000000LL);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    if (stop_requested()) return;
  }
}

// not split: one linear command (source, link, fault plan, paced write loop, summary) whose steps
// share the pty link and the sample source.
void run_sim_imu(const SimImuOptions& o) {
  if (o.format != "si" && o.format != "raw") {
    throw Error("--format must be si or raw", kUsageExitCode);
  }
  imu::FaultSpec spec;
  try {
    spec = imu::FaultSpec::parse(o.faults);
  } catch (const std::invalid_argument& e) {
    throw Error(std::string("--faults: ") + e.what(), kUsageExitCode);
  }
  double rate = 0;
  SimSource source(o, &rate);
  if (!(rate > 0 && rate <= 10000)) throw Error("--rate must be in (0, 10000] Hz", kUsageExitCode);
  // Magnetometer distortion of the simulated board: m_raw = A m + b.
  Eigen::Vector3d hard_iron = Eigen::Vector3d::Zero();
  Eigen::Matrix3d soft_iron = Eigen::Matrix3d::Identity();
  if (!o.mag_hard_iron.empty()) {
    if (o.mag_hard_iron.size() != 3) throw Error("--mag-hard-iron needs 3 values (uT)", kUsageExitCode);
    hard_iron = Eigen::Vector3d(o.mag_hard_iron[0], o.mag_hard_iron[1], o.mag_hard_iron[2]);
  }
  if (!o.mag_soft_iron.empty()) {
    if (o.mag_soft_iron.size() != 9) {
      throw Error("--mag-soft-iron needs 9 values (3x3, row-major)", kUsageExitCode);
    }
    for (int i = 0; i < 9; ++i) soft_iron(i / 3, i % 3) = o.mag_soft_iron[static_cast<std::size_t>(i)];
  }
  // The MPU6050's digital low-pass filter: its datasheet delay on accel and gyro, and the $INF line
  // the GY-87 firmware sends at boot and once a second (docs/SERIAL_PROTOCOL.md "Sensor info").
  std::unique_ptr<sim::SampleDelay> dlpf_delay;
  std::string info_line;
  if (o.dlpf >= 0) {
    const imu::Mpu6050Dlpf* row = imu::mpu6050_dlpf(o.dlpf);
    if (row == nullptr) throw Error("--dlpf must be an MPU6050 DLPF_CFG setting 0..6", kUsageExitCode);
    dlpf_delay = std::make_unique<sim::SampleDelay>(row->accel_delay_ms * 1e-3, row->gyro_delay_ms * 1e-3);
    imu::SensorInfoLine info;
    info.version = 1;
    info.chip = "MPU6050";
    info.setting = o.dlpf;
    info_line = imu::format_info_line(info);
  } else if (o.source == "trajectory" && o.sensor_info) {
    // the simulator's samples at their stamps, no low-pass modelled: delay 0 (a BROAD file's
    // samples carry that sensor's own delay, which this line must not claim)
    info_line = imu::simulated_sensor_info_line();
  }
  const auto info_every = static_cast<uint64_t>(std::max(1.0, std::round(rate)));
  imu::FaultInjector injector(spec);
  install_stop_handlers();
  std::unique_ptr<imu::PtyLink> link;
  try {
    link = std::make_unique<imu::PtyLink>(o.link);
  } catch (const std::exception& e) {
    throw Error(e.what());
  }
  if (!o.quiet) {
    std::fprintf(stderr, "poise sim-imu: %s -> %s, %.1f Hz, %s, faults: %s (Ctrl-C stops)\n",
                 o.link.c_str(), link->slave_name().c_str(), rate, o.source.c_str(),
                 o.faults.empty() ? "none" : o.faults.c_str());
  }
  const auto period_ns = static_cast<int64_t>(std::llround(1e9 / (rate * o.speed)));
  const int64_t start_ns = imu::monotonic_now_ns();
  int64_t boot_ns = start_ns;  // the simulated board's power-on time (reset by disconnects)
  uint32_t seq = 0;
  uint64_t sent = 0;
  uint64_t no_reader = 0;
  uint64_t full = 0;
  uint64_t disconnects = 0;
  const bool raw_format = o.format == "raw";
  bool had_reader = false;
  int64_t next_disconnect_ns =
      spec.disconnect_every_s > 0 ? start_ns + static_cast<int64_t>(spec.disconnect_every_s * 1e9) : 0;
  int64_t paused_ns = 0;  // time spent disconnected: the schedule resumes after it, no catch-up
  for (uint64_t k = 0; !stop_requested(); ++k) {
    if (o.count > 0 && k >= o.count) break;
    const int64_t t_ns = start_ns + paused_ns + static_cast<int64_t>(k) * period_ns;
    if (o.duration_s > 0 && static_cast<double>(t_ns - start_ns) * 1e-9 >= o.duration_s) break;
    sleep_until_ns(t_ns);
    if (stop_requested()) break;
    if (next_disconnect_ns != 0 && t_ns >= next_disconnect_ns) {
      const std::string held = injector.flush();
      if (!held.empty()) link->write(held);
      link->disconnect();
      ++disconnects;
      if (!o.quiet) std::fprintf(stderr, "poise sim-imu: disconnected for %.2f s\n", spec.disconnect_down_s);
      sleep_until_ns(t_ns + static_cast<int64_t>(spec.disconnect_down_s * 1e9));
      try {
        link->reconnect();
      } catch (const std::exception& e) {
        throw Error(e.what());
      }
      had_reader = false;  // power-cycled: it boots again when the reader reopens the port
      paused_ns += imu::monotonic_now_ns() - t_ns;
      next_disconnect_ns = imu::monotonic_now_ns() + static_cast<int64_t>(spec.disconnect_every_s * 1e9);
      if (!o.quiet) std::fprintf(stderr, "poise sim-imu: reconnected at %s\n", link->slave_name().c_str());
      continue;
    }
    if (!link->has_reader()) {  // as a UART with nobody listening: the line is lost, no fault
      ++no_reader;
      had_reader = false;
      continue;
    }
    if (!had_reader) {
      // Opening the port resets the board (Arduino DTR): it boots and starts over.
      had_reader = true;
      source.restart();
      seq = 0;
      boot_ns = t_ns;
      link->write("# poise sim-imu board ready\r\n");
      if (dlpf_delay) dlpf_delay->reset();  // the board restarts: no history
    }
    if (!info_line.empty() && seq % info_every == 0) link->write(info_line);  // at boot, then every second
    ImuSample s;
    if (!source.next(&s)) break;
    if (dlpf_delay) s = dlpf_delay->apply(s);
    if (s.has_mag) s.mag_ut = soft_iron * s.mag_ut + hard_iron;
    const double sensor_s =
        static_cast<double>(t_ns - boot_ns) * 1e-9 * o.speed * (1.0 + o.drift_ppm * 1e-6);
    const auto t_us = static_cast<uint32_t>(
        (static_cast<uint64_t>(std::llround(sensor_s * 1e6)) + o.t_start_us) & 0xFFFFFFFFull);
    const std::string line = make_line(s, seq++, t_us, raw_format);
    const std::string bytes = injector.apply(line);
    if (bytes.empty()) continue;
    switch (link->write(bytes, imu::kSimulatedBoardWaitMs)) {
      case imu::PtyLink::WriteStatus::kWritten: ++sent; break;
      case imu::PtyLink::WriteStatus::kNoReader: ++no_reader; break;
      case imu::PtyLink::WriteStatus::kFull: ++full; break;
      case imu::PtyLink::WriteStatus::kDisconnected: break;
    }
  }
  const std::string held = injector.flush();
  if (!held.empty()) link->write(held);
  sleep_until_ns(imu::monotonic_now_ns() + 100'000'000);  // let the reader drain the last lines
  link.reset();  // removes the symlink
  // Summary on stdout (machine-readable "key: value" lines).
  std::printf("lines_written: %" PRIu64 "\nlines_without_reader: %" PRIu64
              "\nlines_reader_full: %" PRIu64 "\ndisconnects: %" PRIu64 "\n",
              sent, no_reader, full, disconnects);
  for (std::size_t f = 0; f < imu::kFaultCount; ++f) {
    std::printf("fault_%s: %" PRIu64 "\n", imu::to_string(static_cast<imu::Fault>(f)),
                injector.counts()[f]);
  }
  std::fflush(stdout);
}

}  // namespace

void register_imu_cli(CLI::App& app) {
  auto io = std::make_shared<ImuOptions>();
  CLI::App* imu_cmd = app.add_subcommand(
      "imu", "Serial IMU driver: read a port (GY-87 / any board printing the poise protocol) and "
             "publish ImuSample on 'imu' plus driver diagnostics");
  imu_cmd->add_option("--port", io->port, "Serial device or sim-imu link (e.g. /dev/ttyACM0)")->required();
  imu_cmd->add_option("--baud", io->baud, "Baud rate 9600..1000000 (default: config file, else 115200)")
      ->check(CLI::IsMember(imu::supported_bauds()));
  imu_cmd->add_option("--config", io->config, "Driver YAML (limits, raw scales, calibration; see " +
                                               runtime::shipped_file_hint("drivers/imu.yaml") + ")")
      ->check(CLI::ExistingFile);
  imu_cmd->add_option("--name", io->name, "sensor_id of the published samples")->capture_default_str();
  add_dds_profile_option(imu_cmd, &io->profile);
  add_deprecated_alias(imu_cmd, "--profile", "--dds-profile", &io->profile);
  add_domain_option(imu_cmd, &io->domain);
  imu_cmd->add_option("--duration", io->duration_s, "Stop after this many seconds (0: until Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  imu_cmd->add_option("--status-period", io->status_period_s, "Seconds between status lines")
      ->check(CLI::PositiveNumber);
  imu_cmd->add_flag("--quiet", io->quiet, "No status output");
  imu_cmd->add_option("--rt-priority", io->rt_priority,
                      "SCHED_FIFO priority 1-99 for every thread, the serial reader included (0: normal)")
      ->check(CLI::Range(0, 99));
  imu_cmd->add_flag("--lock-memory", io->lock_memory, "mlockall: no page faults on the sensor path");
  imu_cmd->callback([io] { run_imu(*io); });

  auto so = std::make_shared<SimImuOptions>();
  CLI::App* sim_cmd = app.add_subcommand(
      "sim-imu", "Simulated serial IMU: a pseudo-terminal at --link streaming the poise protocol in "
                 "real time, with optional fault injection");
  sim_cmd->add_option("--link", so->link, "Symlink path to create for the device (e.g. /tmp/imu0)")->required();
  sim_cmd->add_option("--source", so->source, "trajectory (sensor simulator) or broad:FILE (BROAD HDF5)")
      ->capture_default_str();
  sim_cmd->add_option("--scenario", so->scenario, "Simulator scenario for --source trajectory "
                                                  "(demo, tour, random_motion, fast_motion, "
                                                  "static_magnet, calibration)")
      ->capture_default_str();
  sim_cmd->add_option("--rate", so->rate_hz, "Sample rate, Hz (default 200, or the BROAD file's)")
      ->check(CLI::Range(0.1, 10000.0));
  sim_cmd->add_option("--faults", so->faults,
                      "Fault SPEC: garbage=P,drop=P,flip=P,truncate=P,dup=P,swap=P,nan=P,"
                      "disconnect=EVERY_S:DOWN_S,seed=N (docs/SERIAL_PROTOCOL.md)");
  sim_cmd->add_option("--format", so->format, "si ($IMU lines) or raw ($RAW register counts)")
      ->capture_default_str();
  sim_cmd->add_option("--duration", so->duration_s, "Stop after this many seconds (0: until Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  sim_cmd->add_option("--count", so->count, "Stop after this many samples (0: no limit)");
  sim_cmd->add_option("--seed", so->seed, "Simulator seed")->capture_default_str();
  sim_cmd->add_option("--drift-ppm", so->drift_ppm, "Sensor clock drift vs host, ppm")
      ->check(CLI::Range(-50000.0, 50000.0));
  sim_cmd->add_option("--t-start-us", so->t_start_us, "Sensor clock at boot, us (test the 2^32 wrap)");
  sim_cmd->add_option("--speed", so->speed, "Speed factor: stream this many times faster than real "
                                            "time (sensor clock included)")
      ->capture_default_str()->check(CLI::Range(0.01, 100.0));
  sim_cmd->add_option("--mag-hard-iron", so->mag_hard_iron, "Distort the magnetometer: offset b, "
                                                            "3 values in uT (m_raw = A m + b)")
      ->delimiter(',')->expected(3);
  sim_cmd->add_option("--mag-soft-iron", so->mag_soft_iron, "Distort the magnetometer: A, 9 values "
                                                            "row-major")
      ->delimiter(',')->expected(9);
  sim_cmd->add_option("--dlpf", so->dlpf,
                      "Model the MPU6050's digital low-pass filter DLPF_CFG N (0..6): delay accel and "
                      "gyro by its datasheet figure and send the firmware's $INF line")
      ->check(CLI::Range(0, 6));
  sim_cmd->add_flag("!--no-sensor-info", so->sensor_info,
                    "Without --dlpf the trajectory sends $INF,1,SIM,,0,0 (its samples have no delay), so "
                    "filters use 0; this flag sends no $INF line: a sensor that says nothing about its "
                    "delay (a BROAD file never sends one)");
  sim_cmd->add_flag("--loop", so->loop, "Repeat a BROAD file forever");
  sim_cmd->add_flag("--quiet", so->quiet, "No progress messages");
  sim_cmd->callback([so] { run_sim_imu(*so); });

  add_calibrate_imu(app);
  add_bench_imu(app);
}

}  // namespace poise::cli
