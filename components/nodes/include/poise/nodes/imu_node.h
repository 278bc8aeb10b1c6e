// The shape every IMU-driven estimator node shares (altitude included): take an ImuSample from
// `imu` -> convert -> step the core -> publish its estimate and FilterDiagnostics on
// `diagnostics`. Subclasses only call the core and map its outputs, which keeps each node a thin
// adapter; decisions about sources are the core's (poise/core/source_report.h).
#pragma once

#include "poise/core/north.h"
#include "poise/core/types.h"
#include "poise/nodes/input_health.h"
#include "poise/nodes/reports.h"
#include "poise/runtime/component.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace poise::nodes {

/// Node-level parameters common to every estimator node (host-file `params`).
struct NodeParams {
  int diagnostics_every = 1;  ///< publish diagnostics every N input samples (1 = input rate)
  /// ... and on a timer with this period, input or not (a dead input shows as silence)
  double diagnostics_period_s = 1.0;
  /// an input silent for longer is reported silent (`<topic>_silent`, status "no input on ...")
  double input_deadline_s = 0.5;
  static const std::vector<std::string>& keys();
};
NodeParams node_params(const runtime::ComponentSpec& spec);

/// The keys of the north configuration every attitude node takes (host-file `params`):
/// `declination_deg`, or `location: {lat_deg, lon_deg, alt_m}` with optional `date`
/// (YYYY-MM-DD, default today, UTC), `magnetic_model` (a .COF file, default the built-in
/// WMM2025) and `seed_field` (default true: the model's |B| and dip seed the field reference).
const std::vector<std::string>& north_keys();
/// Reads and resolves them (ConfigError naming the component and what to fix).
NorthReference north_reference(const runtime::ComponentSpec& spec);

/// The one node shape of every IMU-driven estimator: on each `imu` sample convert -> step the
/// core -> publish the estimate (when the core has one) -> publish diagnostics every
/// `diagnostics_every` input samples, rejected samples included (a core that rejects everything
/// is reported, never silent) -- and on a timer every `diagnostics_period_s`, so a dead input
/// shows as "no input for N s". Every input's sequence gaps (samples lost on the way) and silence
/// against `input_deadline_s` are counted (InputHealth). Subclasses only call their core and
/// convert its outputs; secondary inputs call track_input() from their callbacks.
class ImuEstimatorNode : public runtime::Component {
 public:
  ImuEstimatorNode(const runtime::ComponentSpec& spec, runtime::HostContext& host, std::string component);
  ~ImuEstimatorNode() override;
  void start() override;
  void stop() override;
  [[nodiscard]] std::string status() const override;

 protected:
  /// Steps the core with one sample; false when the core rejected it. Called with mutex() held.
  virtual bool step(const ImuSample& sample) = 0;
  /// Converts the core's estimate for `sample` and writes it; false when the core has none yet.
  virtual bool publish_estimate(const ImuSample& sample) = 0;
  /// The core's per-source report, counters and metrics, 1:1 (sources, counters, metrics).
  virtual void diagnostics(DiagnosticsReport& diag) const = 0;

  /// The lock that serialises step() with other inputs of a subclass (e.g. vision).
  std::mutex& mutex() const { return mutex_; }
  [[nodiscard]] const std::string& sensor_id() const { return sensor_id_; }
  [[nodiscard]] const std::string& component() const { return component_; }
  runtime::HostContext& host() { return host_; }
  /// Accounts one sample of a secondary input `topic` (loss, silence). Call with mutex() held.
  void track_input(const std::string& topic, const std::string& source, uint32_t seq,
                   const eprosima::fastdds::dds::SampleInfo& info);

 private:
  void on_imu(const msg::ImuSample& m, const eprosima::fastdds::dds::SampleInfo& info);
  /// Publishes diagnostics: the core's part from the last diagnostics() call, plus the node's
  /// counters and input health at `now_ns`. Called with mutex_ held.
  void publish_diagnostics(int64_t stamp_ns, uint32_t seq, int64_t now_ns);
  void run_timer();

  runtime::HostContext& host_;
  std::string sensor_id_;
  std::string component_;
  NodeParams params_;
  mutable std::mutex mutex_;
  std::atomic<bool> running_{false};
  std::atomic<uint64_t> received_{0};
  std::atomic<uint64_t> published_{0};
  std::atomic<uint64_t> rejected_{0};
  std::atomic<uint64_t> malformed_{0};  // IMU payloads that did not deserialize (dropped)
  std::atomic<int64_t> last_latency_ns_{0};
  uint64_t since_diagnostics_ = 0;
  InputHealth inputs_;              // guarded by mutex_
  DiagnosticsReport core_report_;   // the core's last diagnostics(), guarded by mutex_
  uint32_t last_seq_ = 0;           // guarded by mutex_
  std::mutex timer_mutex_;
  std::condition_variable timer_cv_;
  bool timer_stop_ = false;
  std::thread timer_;
  std::unique_ptr<dds::Writer<msg::FilterDiagnosticsPubSubType>> diagnostics_writer_;
  std::unique_ptr<dds::Reader<msg::ImuSamplePubSubType>> imu_reader_;
};

/// An attitude estimator's node: publishes AttitudeEstimate on `attitude/<filter>`.
class ImuAttitudeNode : public ImuEstimatorNode {
 public:
  ImuAttitudeNode(const runtime::ComponentSpec& spec, runtime::HostContext& host, std::string filter_id);

 protected:
  /// The core's attitude for `sample` (stamp and seq are filled here); false when it has none.
  virtual bool attitude(AttitudeReport& report) const = 0;
  bool publish_estimate(const ImuSample& sample) override;
  /// The report last published (for subclasses that publish more, e.g. a pose), in the output
  /// frame (true ENU when a declination is configured).
  [[nodiscard]] const AttitudeReport& last_report() const { return report_; }
  /// North as configured: outputs are rotated into true ENU when north().true_north; the core
  /// works in magnetic ENU throughout.
  [[nodiscard]] const NorthReference& north() const { return north_; }

 private:
  NorthReference north_;
  AttitudeReport report_;
  dds::Writer<msg::AttitudeEstimatePubSubType> attitude_writer_;
};

/// The host's monotonic clock in ns (CLOCK_MONOTONIC: the domain of sample stamps). Adapters
/// only: cores never read clocks.
int64_t monotonic_ns();

}  // namespace poise::nodes
