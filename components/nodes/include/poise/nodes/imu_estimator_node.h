// The live node of every IMU-driven estimator (altitude included): a StepRunner
// (poise/nodes/estimator_step.h: the step logic `poise process` runs offline too) on DDS. On each
// ImuSample from `imu`: convert -> step the core -> publish its estimate(s) -> publish
// FilterDiagnostics on `diagnostics` at `diagnostics_rate_hz` (default 5 Hz; counters cumulative;
// every `diagnostics_every` input samples when asked), rejected samples included (a core that
// rejects everything is reported, never silent) -- and on a timer every `diagnostics_period_s`
// while none come otherwise, so a dead input shows as "no input for N s". Every input's sequence
// gaps (samples lost on the way) and silence against `input_deadline_s` are counted
// (InputHealth). The secondary inputs a step uses (`vision_pose`, `vehicle_input`) are subscribed
// here too; the node only translates: DDS in, step, DDS out. A step with an IMU delay
// (imu_delay_s) also reads `imu_info` (transient-local: the delay the IMU's driver publishes) and
// says on stderr which delay it uses, at start and when it changes (poise/nodes/imu_delay.h).
#pragma once

#include "poise/core/types.h"
#include "poise/nodes/estimator_step.h"
#include "poise/runtime/component.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/sensor_infoPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace poise::nodes {

class ImuEstimatorNode : public runtime::Component {
 public:
  ImuEstimatorNode(const runtime::ComponentSpec& spec, runtime::HostContext& host,
                   std::unique_ptr<EstimatorStep> step);
  ~ImuEstimatorNode() override;
  void start() override;
  void stop() override;
  [[nodiscard]] std::string status() const override;
  /// Estimates published (the service watchdog's health check).
  [[nodiscard]] std::optional<uint64_t> produced() const override;

 private:
  /// The DDS writers of what the step declares (StepOutputs).
  class Writers : public StepOutputs {
   public:
    Writers(runtime::HostContext& host, const EstimatorStep& step);
    void attitude(const msg::AttitudeEstimate& m) override;
    void pose(const msg::PoseEstimate& m) override;
    void altitude(const msg::AltitudeEstimate& m) override;
    void diagnostics(const msg::FilterDiagnostics& m) override;

   private:
    std::unique_ptr<dds::Writer<msg::AttitudeEstimatePubSubType>> attitude_;
    std::unique_ptr<dds::Writer<msg::PoseEstimatePubSubType>> pose_;
    std::unique_ptr<dds::Writer<msg::AltitudeEstimatePubSubType>> altitude_;
    dds::Writer<msg::FilterDiagnosticsPubSubType> diagnostics_;
  };

  void on_imu(const msg::ImuSample& m, const eprosima::fastdds::dds::SampleInfo& info);
  void run_timer();

  runtime::HostContext& host_;
  mutable std::mutex mutex_;  // serialises the runner across the readers and the timer
  StepRunner runner_;         // guarded by mutex_ (its malformed counters are atomics)
  Writers writers_;
  std::atomic<bool> running_{false};
  std::mutex timer_mutex_;
  std::condition_variable timer_cv_;
  bool timer_stop_ = false;
  std::thread timer_;
  std::unique_ptr<dds::Reader<msg::ImuSensorInfoPubSubType>> imu_info_reader_;
  std::atomic<uint64_t> imu_info_malformed_{0};
  std::unique_ptr<dds::Reader<msg::ImuSamplePubSubType>> imu_reader_;
  std::unique_ptr<dds::Reader<msg::VisionPosePubSubType>> vision_reader_;
  std::unique_ptr<dds::Reader<msg::VehicleInputPubSubType>> vehicle_reader_;
};

/// A component type whose node is an ImuEstimatorNode around the step `make` builds.
runtime::ComponentType estimator_component(const std::string& type, const std::string& description,
                                           StepFactory make);

/// The host's monotonic clock in ns (CLOCK_MONOTONIC: the domain of sample stamps). Adapters
/// only: cores never read clocks.
int64_t monotonic_ns();

}  // namespace poise::nodes
