// The shape every IMU-driven estimator node shares: take an ImuSample from `imu` -> check it ->
// convert -> step the core -> publish AttitudeEstimate on `attitude/<filter>` and
// FilterDiagnostics on `diagnostics`. Subclasses only implement step() (the core call and the
// report), which keeps each node a thin adapter.
#pragma once

#include "poise/core/types.h"
#include "poise/nodes/reports.h"
#include "poise/runtime/component.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <string>

namespace poise::nodes {

/// Node-level parameters common to every estimator node (host-file `params`).
struct NodeParams {
  int diagnostics_every = 1;  ///< publish diagnostics every N input samples (1 = input rate)
  static const std::vector<std::string>& keys();
};
NodeParams node_params(const runtime::ComponentSpec& spec);

class ImuAttitudeNode : public runtime::Component {
 public:
  ImuAttitudeNode(const runtime::ComponentSpec& spec, runtime::HostContext& host, std::string filter_id);
  ~ImuAttitudeNode() override;
  void start() override;
  void stop() override;
  [[nodiscard]] std::string status() const override;

 protected:
  /// Steps the core with one IMU sample; fills `report` and `diag` when it returns true (publish).
  /// Called with the node's mutex held (from the DDS thread), one sample at a time.
  virtual bool step(const ImuSample& sample, AttitudeReport& report, DiagnosticsReport& diag) = 0;

  /// The lock that serialises step() with other inputs of a subclass (e.g. vision).
  std::mutex& mutex() { return mutex_; }
  [[nodiscard]] const std::string& sensor_id() const { return sensor_id_; }
  [[nodiscard]] const std::string& filter_id() const { return filter_id_; }
  runtime::HostContext& host() { return host_; }
  /// Publishes a report (used by subclasses with extra inputs).
  void publish(const AttitudeReport& report, DiagnosticsReport& diag, bool with_diagnostics);

 private:
  void on_imu(const msg::ImuSample& m);

  runtime::HostContext& host_;
  std::string sensor_id_;
  std::string filter_id_;
  NodeParams params_;
  std::mutex mutex_;
  std::atomic<bool> running_{false};
  std::atomic<uint64_t> received_{0};
  std::atomic<uint64_t> published_{0};
  std::atomic<uint64_t> rejected_{0};
  std::atomic<int64_t> last_latency_ns_{0};
  uint64_t since_diagnostics_ = 0;
  std::unique_ptr<dds::Writer<msg::AttitudeEstimatePubSubType>> attitude_writer_;
  std::unique_ptr<dds::Writer<msg::FilterDiagnosticsPubSubType>> diagnostics_writer_;
  std::unique_ptr<dds::Reader<msg::ImuSamplePubSubType>> imu_reader_;
};

/// The host's monotonic clock in ns (CLOCK_MONOTONIC: the domain of sample stamps). Adapters
/// only: cores never read clocks.
int64_t monotonic_ns();

}  // namespace poise::nodes
