// The serial IMU driver as a DDS component: port -> ImuDriver -> `imu` topic (ImuSample),
// `imu_info` (ImuSensorInfo: the sensor's group delay from the firmware's $INF line, when it
// sends one; transient-local) and `diagnostics` (FilterDiagnostics, component_name "imu_driver",
// once per diagnostics period).
// Runs its own reader thread; survives unplug/replug (PortReader). The reading thread never
// writes to DDS: samples and diagnostics go through PublishQueues whose writer threads may block
// (a link cut) without stopping the serial port from being read (docs/NETWORK.md).
//
// Component parameters (host file or `poise imu` options):
//   port: /dev/ttyACM0        (required)
//   baud: 115200              (overrides serial.baud of the driver config)
//   config_file: imu.yaml     (driver YAML, config/drivers/imu.yaml format) -- or the same
//                             sections inline: serial, protocol, limits, raw, clock, calibration
//   diagnostics_period_s: 1.0
//   publish_queue: 400        (samples between the reading thread and the DDS writer thread; when
//                             full the oldest is dropped and counted: dropped_queue_full)
//   max_age_s: 0.5            (a sample older than this when its turn to be written comes is
//                             dropped and counted, dropped_stale, never delivered late; 0 = off)
//   reliable: false           (true: publish `imu` with the reliable "estimate" QoS instead of the
//                             best-effort "sensor" one, e.g. for recording or exact-count tests)
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/sensor_infoPubSubTypes.h>

#include "poise/dds/publish_queue.h"
#include "poise/imu/config.h"
#include "poise/imu/driver.h"
#include "poise/imu/serial_port.h"
#include "poise/nodes/reports.h"
#include "poise/runtime/component.h"

namespace poise::imu {

struct ImuNodeOptions {
  std::string port;
  DriverConfig config;
  double diagnostics_period_s = 1.0;
  bool reliable = false;
  std::size_t publish_queue = 400;
  double max_age_s = 0.5;
  bool log_to_stderr = true;
};

/// Parses component parameters into options (ConfigError with what to fix).
ImuNodeOptions imu_node_options(const runtime::ComponentSpec& spec);

/// The ImuSensorInfo message of a sensor delay.
msg::ImuSensorInfo to_info_msg(const SensorDelay& delay, const std::string& sensor_id, int64_t stamp_ns);

/// Diagnostics report of the driver (pure; counters per reject reason, rates, clock).
nodes::DiagnosticsReport driver_diagnostics(const DriverStats& stats,
                                            const RateLatencyMeter::Summary& rate, bool connected,
                                            uint64_t connects, int64_t stamp_ns, uint32_t seq);

/// The counts when the driver stops, one line: samples read (lines, bytes), published, rejected
/// by reason (the reasons that occurred), lost to sequence gaps, dropped by the publish queue.
std::string final_counts(const DriverStats& stats, const dds::PublishQueue<msg::ImuSample>::Stats& queue);

/// The running status line: connection, rate, counts read and published, drops, latency, clock
/// (and clock_ratio_problem() when there is one).
std::string status_line(const DriverStats& stats, const RateLatencyMeter::Summary& rate,
                        const dds::PublishQueue<msg::ImuSample>::Stats& queue, bool connected);

/// status() while running: status_line() with the counts as of the reading thread's last tick
/// (each read from the port, at least every poll_ms, 50 ms) and the publish queue's as of the call,
/// so that it agrees with the filters' lines printed next to it; the rate and latency are over the
/// window that ended at the last diagnostics. After stop(): final_counts().
class ImuDriverNode : public runtime::Component {
 public:
  ImuDriverNode(const ImuNodeOptions& options, const std::string& sensor_id,
                runtime::HostContext& host);
  ~ImuDriverNode() override;
  void start() override;
  void stop() override;
  [[nodiscard]] std::string status() const override;
  /// Samples written to DDS (the service watchdog's health check).
  [[nodiscard]] std::optional<uint64_t> produced() const override { return imu_queue_.stats().written; }

 private:
  void on_sample(const ImuSample& sample, const SampleInfo& info);
  void on_tick(int64_t now_ns);
  void on_delay(const SensorDelay& delay);

  ImuNodeOptions options_;
  std::string sensor_id_;
  runtime::HostContext& host_;
  dds::Writer<msg::ImuSamplePubSubType> imu_writer_;
  dds::Writer<msg::FilterDiagnosticsPubSubType> diag_writer_;
  dds::Writer<msg::ImuSensorInfoPubSubType> info_writer_;
  ImuDriver driver_;
  PortReader reader_;
  RateLatencyMeter meter_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  // Declared after the writers they write to (destroyed first, which stops their threads).
  dds::PublishQueue<msg::ImuSample> imu_queue_;
  dds::PublishQueue<msg::FilterDiagnostics> diag_queue_;
  dds::PublishQueue<msg::ImuSensorInfo> info_queue_;
  int64_t next_diag_ns_ = 0;
  uint32_t diag_seq_ = 0;
  int64_t last_stamp_ns_ = 0;
  mutable std::mutex status_mutex_;  // guards the status_ members and final_
  DriverStats status_stats_;             // driver_.stats() at the last tick
  RateLatencyMeter::Summary status_rate_;  // at the last diagnostics
  bool status_connected_ = false;
  bool status_ticked_ = false;
  std::string final_;                    // final_counts() once stopped
  uint64_t warned_no_valid_at_bytes_ = 0;
  bool warned_clock_ = false;
};

}  // namespace poise::imu

namespace poise::runtime {
/// Registers the "imu_driver" component type (poise_add_component_module).
void register_imu_driver(ComponentRegistry& registry);
}  // namespace poise::runtime
