// `poise demo`: a simulated IMU stream published over DDS and received by a subscriber on another
// participant, printed live. With no hardware this is the smallest honest end-to-end run.
#include "poise/cli/common.h"
#include "poise/dds/convert.h"
#include "poise/dds/participant.h"

#include <poise/msg/imuPubSubTypes.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <thread>

namespace poise::cli {
namespace {

struct DemoOptions {
  int domain = 0;
  double duration_s = 10.0;
  double rate_hz = 200.0;
};

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

/// A sensor rotating slowly about world up at rest in a 50 uT field with 60 deg dip.
ImuSample synthetic_sample(uint32_t seq, int64_t stamp_ns, double t_s) {
  constexpr double kGravity = 9.80665;
  constexpr double kRate = 0.5;  // rad/s about z
  const double yaw = kRate * t_s;
  ImuSample s;
  s.stamp_ns = stamp_ns;
  s.seq = seq;
  s.accel_mps2 = {0.0, 0.0, kGravity};
  s.gyro_rps = {0.0, 0.0, kRate};
  const Eigen::Vector3d field_world(0.0, 25.0, -43.3);  // ENU, uT
  s.mag_ut = Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitZ()) * field_world;
  s.pressure_pa = 101325.0;
  s.temperature_c = 25.0;
  s.has_pressure = true;
  s.has_temperature = true;
  return s;
}

void run_demo(const DemoOptions& options) {
  install_stop_handlers();
  dds::Participant source({options.domain, "", "", "poise_demo_imu"});
  dds::Participant sink({options.domain, "", "", "poise_demo_monitor"});
  std::atomic<uint64_t> received{0};
  std::atomic<int64_t> last_latency_ns{0};
  std::atomic<double> last_yaw_deg{0.0};
  dds::Reader<msg::ImuSamplePubSubType> reader(
      sink, "imu", [&](const msg::ImuSample& m, const auto& /*info*/) {
        received.fetch_add(1);
        last_latency_ns.store(now_ns() - m.header().stamp_ns());
        const Eigen::Vector3d mag = dds::from_msg(m.mag_ut());
        last_yaw_deg.store(std::atan2(-mag.x(), mag.y()) * 180.0 / M_PI);
      });
  dds::Writer<msg::ImuSamplePubSubType> writer(source, "imu");
  std::fprintf(stderr, "poise demo: simulated IMU at %.0f Hz on domain %d for %.0f s (Ctrl-C stops)\n",
               options.rate_hz, options.domain, options.duration_s);
  writer.wait_for_readers(1, std::chrono::seconds(5));

  const auto period = std::chrono::nanoseconds(static_cast<int64_t>(1e9 / options.rate_hz));
  const auto start = std::chrono::steady_clock::now();
  auto next = start;
  auto next_print = start;
  uint32_t seq = 0;
  uint64_t published = 0;
  while (!stop_requested()) {
    const auto now = std::chrono::steady_clock::now();
    const double t_s = std::chrono::duration<double>(now - start).count();
    if (t_s >= options.duration_s) {
      break;
    }
    if (writer.write(dds::to_msg(synthetic_sample(seq++, now_ns(), t_s), "sim_imu"))) {
      ++published;
    }
    if (now >= next_print) {
      std::printf("t=%5.1fs published=%7llu received=%7llu latency=%6.1fus heading(mag)=%7.1fdeg\n",
                  t_s, static_cast<unsigned long long>(published),
                  static_cast<unsigned long long>(received.load()),
                  static_cast<double>(last_latency_ns.load()) / 1e3, last_yaw_deg.load());
      std::fflush(stdout);
      next_print += std::chrono::milliseconds(500);
    }
    next += period;
    std::this_thread::sleep_until(next);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  std::printf("done: published %llu, received %llu\n", static_cast<unsigned long long>(published),
              static_cast<unsigned long long>(received.load()));
  if (received.load() == 0) {
    throw Error("the subscriber received no sample: DDS discovery failed on domain " +
                std::to_string(options.domain));
  }
}

}  // namespace

void register_demo_commands(CLI::App& app) {
  auto options = std::make_shared<DemoOptions>();
  CLI::App* demo = app.add_subcommand(
      "demo", "Run the main job on the embedded default: simulated IMU -> DDS -> live output");
  add_domain_option(demo, &options->domain);
  demo->add_option("--duration", options->duration_s, "Run time, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  demo->add_option("--rate", options->rate_hz, "IMU rate, Hz")
      ->check(CLI::Range(1.0, 2000.0))
      ->capture_default_str();
  demo->callback([options] { run_demo(*options); });
}

}  // namespace poise::cli
