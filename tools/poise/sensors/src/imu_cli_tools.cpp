// `poise calibrate imu` and `poise bench imu`.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/LU>

#include <poise/msg/imuPubSubTypes.h>

#include "poise/cli/common.h"
#include "poise/dds/convert.h"
#include "poise/dds/participant.h"
#include "poise/imu/config.h"
#include "poise/imu/driver.h"
#include "poise/imu/mag_calibration.h"
#include "poise/imu/pty_link.h"
#include "poise/imu/serial_port.h"

namespace poise::cli {
namespace {

// ---------------------------------------------------------------- poise calibrate imu
struct CalibrateOptions {
  std::string port;
  std::string topic;
  int baud = 0;
  std::string config;
  std::string output;
  double still_s = 5.0;
  double coverage = 0.75;
  double timeout_s = 300.0;
  double field_ut = 0.0;
  bool skip_still = false;
  int domain = 0;
  std::string profile;  // DDS participant profile ("" = $POISE_DDS_PROFILE, else poise_default)
};

std::string bar(double fraction, int width = 24) {
  const int n = static_cast<int>(std::clamp(fraction, 0.0, 1.0) * width + 0.5);
  return "[" + std::string(static_cast<std::size_t>(n), '#') +
         std::string(static_cast<std::size_t>(width - n), '-') + "]";
}

void print_progress(const imu::CalibrationSession& s, bool final_line) {
  const auto p = s.progress();
  if (p.phase == imu::CalibrationSession::Phase::kStill) {
    std::fprintf(stderr, "\r[1/2] hold the IMU still        %s %3.0f%% %-10s", bar(p.still_fraction).c_str(),
                 100.0 * p.still_fraction, p.moving ? "(moving)" : "");
  } else {
    std::fprintf(stderr, "\r[2/2] rotate through all orientations: coverage %s %3.0f%%  points %5zu  "
                         "fit residual %.2f uT   ",
                 bar(p.coverage).c_str(), 100.0 * p.coverage, p.mag_points, p.residual_ut);
  }
  if (final_line) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

// not split: the guided calibration's script in the order the user follows it (still, rotate, fit,
// write).
void run_calibrate(const CalibrateOptions& o) {
  if (o.port.empty() == o.topic.empty()) {
    throw Error("give exactly one of --port PATH or --imu-topic NAME", kUsageExitCode);
  }
  imu::DriverConfig config;
  if (!o.config.empty()) {
    try {
      config = imu::load_driver_config(o.config);
    } catch (const imu::ConfigError& e) {
      throw Error(e.what());
    }
  }
  if (o.baud != 0) config.serial.baud = o.baud;
  const std::string output = !o.output.empty() ? o.output : (!o.config.empty() ? o.config : "imu.yaml");
  imu::CalibrationParams cp;
  cp.still_s = o.still_s;
  cp.coverage_target = o.coverage;
  imu::CalibrationSession session(cp);
  if (o.skip_still) session.skip_still();
  install_stop_handlers();
  const int64_t t0 = imu::monotonic_now_ns();
  const auto timed_out = [&] {
    return static_cast<double>(imu::monotonic_now_ns() - t0) * 1e-9 > o.timeout_s;
  };
  int64_t next_print = 0;
  const auto tick = [&](int64_t now) {
    if (now >= next_print) {
      print_progress(session, false);
      next_print = now + 250'000'000;
    }
  };
  std::fprintf(stderr, "poise calibrate imu: step 1 holds the IMU still for %.0f s (gyro bias); step 2 "
                       "rotates it slowly through every orientation (magnetometer). Ctrl-C aborts.\n",
               o.still_s);
  if (!o.port.empty()) {
    imu::ImuDriver driver(config.params, config.calibration,
                          [&session](const ImuSample&, const imu::SampleInfo& info) {
                            session.add(info.raw, info.sensor_ns);
                          });
    imu::PortReader reader(
        imu::ReaderOptions{o.port, config.serial},
        driver, [](const std::string& m) { std::fprintf(stderr, "\n%s\n", m.c_str()); });
    reader.run([&] { return session.done() || stop_requested() || timed_out(); }, tick);
  } else {
    dds::ParticipantOptions po;
    po.domain = o.domain;
    po.profile = o.profile;
    po.name = "poise calibrate imu";
    std::mutex mu;
    std::deque<ImuSample> queue;
    dds::Participant participant(po);
    dds::Reader<msg::ImuSamplePubSubType> reader(
        participant, o.topic, [&](const msg::ImuSample& m, const eprosima::fastdds::dds::SampleInfo&) {
          std::lock_guard<std::mutex> lock(mu);
          if (queue.size() < 100000) queue.push_back(dds::from_msg(m));
        });
    while (!session.done() && !stop_requested() && !timed_out()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      std::deque<ImuSample> batch;
      {
        std::lock_guard<std::mutex> lock(mu);
        batch.swap(queue);
      }
      for (const auto& s : batch) session.add(config.calibration.invert(s), s.stamp_ns);
      tick(imu::monotonic_now_ns());
    }
  }
  print_progress(session, true);
  if (stop_requested()) throw Error("calibration aborted; nothing written");
  if (!session.has_gyro_bias() && !o.skip_still) {
    throw Error("the IMU never stayed still for " + std::to_string(o.still_s) +
                " s (or no data arrived): put it down on a table and run again; nothing written");
  }
  if (!session.done()) {
    if (session.mag_points().size() < 100) {
      throw Error("timed out with only " + std::to_string(session.mag_points().size()) +
                  " magnetometer points: rotate the IMU through all orientations; nothing written");
    }
    std::fprintf(stderr, "timed out before full coverage: fitting with what was collected\n");
    session.finish();
  }
  imu::EllipsoidFit fit = session.mag_fit();
  if (o.field_ut > 0 && fit.ok) fit = imu::fit_ellipsoid(session.mag_points(), o.field_ut);
  if (!fit.ok) throw Error("magnetometer fit failed: " + fit.error + "; nothing written");
  const auto& gb = session.gyro_bias_rps();
  if (session.has_gyro_bias()) {
    std::printf("gyro bias: [%.6f, %.6f, %.6f] rad/s (noise %.5f rad/s)\n", gb.x(), gb.y(), gb.z(),
                session.gyro_noise_rps());
    config.calibration.gyro_bias_rps = gb;
  }
  std::printf("magnetometer: %zu points, coverage %.0f%%\n", fit.points, 100.0 * session.progress().coverage);
  std::printf("  hard iron: [%.3f, %.3f, %.3f] uT\n", fit.hard_iron_ut.x(), fit.hard_iron_ut.y(),
              fit.hard_iron_ut.z());
  std::printf("  radii: %.2f %.2f %.2f uT -> field %.2f uT\n", fit.radii_ut.x(), fit.radii_ut.y(),
              fit.radii_ut.z(), fit.field_ut);
  std::printf("  residual: %.3f uT rms (magnitude spread before correction: %.3f uT)\n",
              fit.residual_rms_ut, fit.spread_before_ut);
  config.calibration.mag_hard_iron_ut = fit.hard_iron_ut;
  config.calibration.mag_soft_iron = fit.soft_iron;
  const std::string invalid = config.calibration.validate();
  if (!invalid.empty()) {
    throw Error("the fitted calibration is implausible (" + invalid +
                "): repeat step 2 away from metal; nothing written");
  }
  try {
    imu::save_driver_config(config, output);
  } catch (const imu::ConfigError& e) {
    throw Error(e.what());
  }
  std::printf("wrote %s (use: poise imu --port ... --config %s)\n", output.c_str(), output.c_str());
}

// ---------------------------------------------------------------- poise bench imu
struct BenchOptions {
  uint64_t lines = 2'000'000;
  bool latency = false;
  double rate_hz = 1000.0;
  double seconds = 10.0;
  int domain = 0;
  std::string profile;  // DDS participant profile ("" = $POISE_DDS_PROFILE, else poise_default)
};

std::vector<std::string> bench_lines(std::size_t n) {
  std::vector<std::string> out;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    imu::RawSample s;
    s.seq = static_cast<uint32_t>(i);
    s.t_us = static_cast<uint32_t>(i * 1000);
    const double x = static_cast<double>(i);
    s.accel_mps2 = {0.1 * std::sin(x), 0.2 * std::cos(x), 9.81};
    s.gyro_rps = {0.01 * std::sin(0.1 * x), -0.02, 0.3 * std::cos(0.01 * x)};
    s.mag_ut = {21.5 + std::sin(x), -3.2, -42.7};
    s.has_pressure = true;
    s.pressure_pa = 101325.0 + x * 0.01;
    s.has_temperature = true;
    s.temperature_c = 24.5;
    out.push_back(imu::format_imu_line(s));
  }
  return out;
}

void bench_parser(const BenchOptions& o) {
  constexpr std::size_t kDistinct = 4096;
  const auto lines = bench_lines(kDistinct);
  std::vector<std::string> bare;
  for (const auto& l : lines) bare.push_back(l.substr(0, l.size() - 2));
  const imu::LineParser parser;
  uint64_t ok = 0;
  auto t0 = std::chrono::steady_clock::now();
  for (uint64_t i = 0; i < o.lines; ++i) ok += parser.parse(bare[i % kDistinct]).ok ? 1u : 0u;
  double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("parser:  %.3g lines/s (%" PRIu64 " lines, %" PRIu64 " valid, %.2f s; %.0f ns/line)\n",
              static_cast<double>(o.lines) / dt, o.lines, ok, dt, dt * 1e9 / static_cast<double>(o.lines));
  // Full driver path (framing, parsing, sequence, clock sync, calibration) on one byte stream.
  std::string stream;
  for (const auto& l : lines) stream += l;
  uint64_t samples = 0;
  imu::ImuDriver driver({}, {}, [&samples](const ImuSample&, const imu::SampleInfo&) { ++samples; });
  const uint64_t reps = std::max<uint64_t>(1, o.lines / kDistinct);
  t0 = std::chrono::steady_clock::now();
  int64_t now = 0;
  for (uint64_t r = 0; r < reps; ++r) {
    driver.reset();  // each repetition restarts seq at 0 (a sensor restart), like a replug
    for (std::size_t i = 0; i < stream.size(); i += 512) {
      now += 1000000;
      driver.feed(stream.data() + i, std::min<std::size_t>(512, stream.size() - i), now);
    }
  }
  dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("driver:  %.3g lines/s, %.1f MB/s (%" PRIu64 " samples out of %" PRIu64 " lines, %.2f s)\n",
              static_cast<double>(samples) / dt,
              static_cast<double>(stream.size() * reps) / dt / 1e6, samples, reps * kDistinct, dt);
}

// not split: one benchmark's fixed sequence (build the stream, time parse, time framing, print).
void bench_latency(const BenchOptions& o) {
  // Device: a pty; driver: `poise imu` in a child process; subscriber: this process.
  const std::string link = "/tmp/poise-bench-imu-" + std::to_string(::getpid());
  imu::PtyLink pty(link);
  char self[4096] = {};
  const ssize_t n = ::readlink("/proc/self/exe", self, sizeof self - 1);
  if (n <= 0) throw Error("cannot find the poise executable (/proc/self/exe)");
  const std::string domain = std::to_string(o.domain);
  const pid_t child = ::fork();
  if (child == 0) {
    if (!o.profile.empty()) {
      ::execl(self, self, "imu", "--port", link.c_str(), "--domain", domain.c_str(), "--dds-profile",
              o.profile.c_str(), "--quiet", static_cast<char*>(nullptr));
    }
    ::execl(self, self, "imu", "--port", link.c_str(), "--domain", domain.c_str(), "--quiet",
            static_cast<char*>(nullptr));
    std::_Exit(127);
  }
  if (child < 0) throw Error("fork failed");
  struct ChildGuard {
    pid_t pid;
    ~ChildGuard() {
      ::kill(pid, SIGINT);
      int st = 0;
      for (int i = 0; i < 300 && ::waitpid(pid, &st, WNOHANG) == 0; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
      if (::waitpid(pid, &st, WNOHANG) == 0) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &st, 0);
      }
    }
  } guard{child};
  const auto total = static_cast<std::size_t>(o.rate_hz * o.seconds);
  std::vector<int64_t> written(total, 0);
  std::vector<int64_t> latency;
  std::vector<int64_t> stamp_error;  // stamp - true sampling instant (the write time), ns
  latency.reserve(total);
  stamp_error.reserve(total);
  std::mutex mu;
  std::atomic<uint64_t> received{0};
  dds::ParticipantOptions po;
  po.domain = o.domain;
  po.profile = o.profile;
  po.name = "poise bench imu";
  dds::Participant participant(po);
  dds::Reader<msg::ImuSamplePubSubType> reader(
      participant, "imu", [&](const msg::ImuSample& m, const eprosima::fastdds::dds::SampleInfo&) {
        const int64_t now = imu::monotonic_now_ns();
        const uint32_t seq = m.header().seq();
        std::lock_guard<std::mutex> lock(mu);
        if (seq < written.size() && written[seq] != 0) {
          latency.push_back(now - written[seq]);
          stamp_error.push_back(m.header().stamp_ns() - written[seq]);
        }
        received.fetch_add(1);
      });
  std::fprintf(stderr, "bench imu: waiting for `poise imu` (pid %d) to connect and match...\n", child);
  // Warm-up: stream until the subscriber receives samples (the driver connected and matched).
  const int64_t deadline = imu::monotonic_now_ns() + 20'000'000'000LL;
  uint32_t warm_seq = 4000000000u;
  const int64_t boot = imu::monotonic_now_ns();
  while (received.load() < 50) {
    if (imu::monotonic_now_ns() > deadline) throw Error("no sample reached the subscriber within 20 s");
    const int64_t now = imu::monotonic_now_ns();
    imu::RawSample s;
    s.seq = warm_seq++;
    s.t_us = static_cast<uint32_t>((now - boot) / 1000);
    s.accel_mps2 = {0, 0, 9.81};
    s.mag_ut = {20, 0, -40};
    pty.write(imu::format_imu_line(s));
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  // The measured run restarts seq at 0 (the driver resyncs) after a short pause.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  {
    std::lock_guard<std::mutex> lock(mu);
    latency.clear();
    stamp_error.clear();
  }
  const auto period = static_cast<int64_t>(1e9 / o.rate_hz);
  const int64_t start = imu::monotonic_now_ns();
  uint64_t not_written = 0;
  for (std::size_t k = 0; k < total; ++k) {
    const int64_t t = start + static_cast<int64_t>(k) * period;
    while (imu::monotonic_now_ns() < t) {
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
    imu::RawSample s;
    s.seq = static_cast<uint32_t>(k);
    s.t_us = static_cast<uint32_t>((imu::monotonic_now_ns() - boot) / 1000);
    s.accel_mps2 = {0.01, 0.02, 9.81};
    s.gyro_rps = {0.001, 0.002, 0.003};
    s.mag_ut = {20, 1, -40};
    const std::string line = imu::format_imu_line(s);
    {
      std::lock_guard<std::mutex> lock(mu);
      written[k] = imu::monotonic_now_ns();
    }
    if (pty.write(line) != imu::PtyLink::WriteStatus::kWritten) ++not_written;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  std::vector<int64_t> lat;
  std::vector<int64_t> err;
  {
    std::lock_guard<std::mutex> lock(mu);
    lat = latency;
    err = stamp_error;
  }
  if (lat.empty()) throw Error("no measured sample was received");
  std::sort(lat.begin(), lat.end());
  const auto pct = [&lat](double q) {
    return static_cast<double>(lat[std::min(lat.size() - 1, static_cast<std::size_t>(q * static_cast<double>(lat.size())))]) * 1e-6;
  };
  std::printf("latency line written -> sample received (other process, %.0f Hz, %.0f s): "
              "p50 %.3f ms, p99 %.3f ms, max %.3f ms; received %zu of %zu (%" PRIu64 " not written)\n",
              o.rate_hz, o.seconds, pct(0.5), pct(0.99), static_cast<double>(lat.back()) * 1e-6,
              lat.size(), total, not_written);
  // The sensor time of each line is taken right before it is written, so the written instant is
  // the true sampling instant: the stamp error shows the clock estimation (offset + drift).
  std::sort(err.begin(), err.end());
  const auto epct = [&err](double q) {
    return static_cast<double>(err[std::min(err.size() - 1, static_cast<std::size_t>(q * static_cast<double>(err.size())))]) * 1e-6;
  };
  std::printf("stamp - true sampling instant: p1 %.3f ms, p50 %.3f ms, p99 %.3f ms\n", epct(0.01),
              epct(0.5), epct(0.99));
}

}  // namespace

void add_calibrate_imu(CLI::App& app) {
  CLI::App* group = subcommand_group(app, "calibrate", "Guided sensor calibration");
  auto o = std::make_shared<CalibrateOptions>();
  CLI::App* cmd = group->add_subcommand(
      "imu", "Gyro bias (still period) + magnetometer hard/soft iron (ellipsoid fit over a "
             "rotation sequence) from the live stream; writes the driver YAML");
  cmd->add_option("--port", o->port, "Serial device (or sim-imu link) to read");
  cmd->add_option("--imu-topic", o->topic, "Or: an ImuSample topic (e.g. imu) published by `poise imu`");
  add_deprecated_alias(cmd, "--topic", "--imu-topic", &o->topic);
  cmd->add_option("--baud", o->baud, "Baud rate for --port")->check(CLI::IsMember(imu::supported_bauds()));
  cmd->add_option("--config", o->config, "Current driver YAML (limits, raw scales; with --imu-topic also "
                                         "the calibration the publisher applies)")
      ->check(CLI::ExistingFile);
  add_output_file_option(cmd, &o->output, "the driver YAML (default: --config, else ./imu.yaml)", false);
  cmd->add_option("--still-s", o->still_s, "Still period for the gyro bias, s")->capture_default_str()
      ->check(CLI::Range(0.5, 120.0));
  cmd->add_option("--coverage", o->coverage, "Orientation coverage to reach before fitting (0..1)")
      ->capture_default_str()->check(CLI::Range(0.1, 1.0));
  cmd->add_option("--timeout", o->timeout_s, "Give up after this many seconds")->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--field-ut", o->field_ut, "Known local field magnitude, uT (default: fitted)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--skip-still", o->skip_still, "Keep the current gyro bias; only fit the magnetometer");
  add_domain_option(cmd, &o->domain);
  add_dds_profile_option(cmd, &o->profile);
  cmd->callback([o] { run_calibrate(*o); });
}

void add_bench_imu(CLI::App& app) {
  CLI::App* group = subcommand_group(app, "bench", "Benchmarks (figures printed, not asserted)");
  auto o = std::make_shared<BenchOptions>();
  CLI::App* cmd = group->add_subcommand(
      "imu", "Serial IMU: parser and driver lines/s; with --latency, line written -> sample "
             "received by a subscriber in another process (p50/p99)");
  cmd->add_option("--lines", o->lines, "Lines to parse")->capture_default_str();
  cmd->add_flag("--latency", o->latency, "Also measure the end-to-end latency through `poise imu`");
  cmd->add_option("--rate", o->rate_hz, "Line rate for --latency, Hz")->capture_default_str()
      ->check(CLI::Range(1.0, 5000.0));
  cmd->add_option("--duration", o->seconds, "Duration of the --latency run, s")->capture_default_str()
      ->check(CLI::Range(0.5, 600.0));
  add_deprecated_alias(cmd, "--seconds", "--duration", &o->seconds)->check(CLI::Range(0.5, 600.0));
  add_domain_option(cmd, &o->domain);
  add_dds_profile_option(cmd, &o->profile);
  cmd->callback([o] {
    bench_parser(*o);
    if (o->latency) bench_latency(*o);
  });
}

}  // namespace poise::cli
