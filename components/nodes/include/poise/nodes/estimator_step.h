// The step logic of every estimator component, without DDS and without clocks: what the live node
// (poise/nodes/imu_estimator_node.h) and `poise process` (offline, poise/process/process.h) both run, so that
// offline equals live when the inputs come in the same order.
//
//   EstimatorStep  one component's core and its conversions: input -> core -> messages
//   StepOutputs    where the messages go (DDS writers live, MCAP channels offline)
//   StepRunner     the node's shape around a step: counters, input health, the estimate after
//                  each accepted IMU sample, diagnostics at `diagnostics_rate_hz` (or every
//                  `diagnostics_every` samples when asked); the time comes from an injected clock
//                  (the host's monotonic clock live, the stamp of the input being processed
//                  offline)
#pragma once

#include "poise/core/north.h"
#include "poise/core/types.h"
#include "poise/dds/topics.h"
#include "poise/nodes/imu_delay.h"
#include "poise/nodes/input_age.h"
#include "poise/nodes/input_health.h"
#include "poise/nodes/reports.h"
#include "poise/runtime/component.h"

#include <poise/msg/diagnostics.h>
#include <poise/msg/estimates.h>
#include <poise/msg/vision.h>
#include <poise/msg/imu.h>
#include <poise/msg/sensor_info.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace poise::nodes {

/// Node-level parameters common to every estimator node (host-file `params`).
struct NodeParams {
  /// Diagnostics on the input path at most this often (Hz, by the runner's clock). Every counter
  /// in them is cumulative (samples, rejections by reason, per-source fused/rejected counts), so
  /// nothing is lost between two; what is per step (a source's innovation, this step's reason)
  /// is the step's at the time of publishing. 5 Hz: about 1.3 kB/s per component.
  double diagnostics_rate_hz = 5.0;
  /// > 0: instead of the rate, every N input samples (1: per sample, every decision; for
  /// debugging a filter, about 200x the bytes at 200 Hz). 0: by diagnostics_rate_hz.
  int diagnostics_every = 0;
  /// With no diagnostics for this long (a silent input), on a timer (live only), so a dead input
  /// shows as "no input for N s".
  double diagnostics_period_s = 1.0;
  /// an input silent for longer is reported silent (`<topic>_silent`, status "no input on ..."),
  /// and a sample older than this when it arrives is stale: counted (`<topic>_stale`), never fused
  double input_deadline_s = 0.5;
  /// How a sample's age is judged (poise/nodes/input_age.h): `relative` (sound whatever the
  /// publisher's clock), `host_clock` (stamps on this host's clock only), `off`. Live only: `poise
  /// process` has no arrival times (its clock is the stamps) and runs with `off`.
  AgeMethod input_age = AgeMethod::kRelative;
  /// The IMU this component follows (its samples' sensor_id); empty: the first one heard. Samples
  /// of any other sensor on the topic are never stepped (a filter fed two interleaved sensors, or
  /// anyone else publishing on the topic, would fuse both): counted (`imu_other_sensor`), and
  /// said once in the log.
  std::string imu_sensor_id;
  static const std::vector<std::string>& keys();
};
NodeParams node_params(const runtime::ComponentSpec& spec);

/// The keys of the north configuration every attitude node takes (host-file `params`):
/// `declination_deg`, or `location: {lat_deg, lon_deg, alt_m}` with optional `date`
/// (YYYY-MM-DD, default today, UTC), `magnetic_model` (a .COF file, default the built-in
/// WMM2025) and `seed_field` (default true: the model's |B| and dip seed the field reference).
const std::vector<std::string>& north_keys();
/// Reads and resolves them (ConfigError naming the component and what to fix). Reads the date
/// (UTC today) when a location comes without one: configuration, never per sample.
NorthReference north_reference(const runtime::ComponentSpec& spec);

/// Where the messages of a step go. A step writes only the kinds it declares (EstimatorStep::kinds).
class StepOutputs {
 public:
  virtual ~StepOutputs() = default;
  virtual void attitude(const msg::AttitudeEstimate& m) = 0;
  virtual void pose(const msg::PoseEstimate& m) = 0;
  virtual void altitude(const msg::AltitudeEstimate& m) = 0;
  virtual void diagnostics(const msg::FilterDiagnostics& m) = 0;
};

/// Output kinds (bits) and secondary inputs of a step.
enum StepKind : unsigned { kAttitudeOut = 1U, kPoseOut = 2U, kAltitudeOut = 4U };

/// One estimator component's core and the conversions around it. No DDS, no clock, no logging.
class EstimatorStep {
 public:
  /// `sensor_id`: the instance name (sensor_id of every message); `component`: the filter id
  /// (attitude/<component>, pose/<component>, FilterDiagnostics.component_name).
  EstimatorStep(std::string sensor_id, std::string component)
      : sensor_id_(std::move(sensor_id)), component_(std::move(component)) {}
  virtual ~EstimatorStep() = default;
  EstimatorStep(const EstimatorStep&) = delete;
  EstimatorStep& operator=(const EstimatorStep&) = delete;

  /// StepKind bits of what estimate() writes.
  [[nodiscard]] virtual unsigned kinds() const = 0;
  /// Steps the core with one IMU sample; false when the core rejected it.
  virtual bool step(const ImuSample& sample) = 0;
  /// Writes the core's estimate(s) for `sample`; false when the core has none yet.
  virtual bool estimate(const ImuSample& sample, StepOutputs& out) = 0;
  /// The core's per-source report, counters and metrics, 1:1.
  virtual void diagnostics(DiagnosticsReport& diag) const = 0;

  /// Secondary inputs: the live node subscribes to those a step uses, `poise process` feeds the
  /// recorded ones in stamp order.
  [[nodiscard]] virtual bool uses_vision() const { return false; }
  virtual void vision(const msg::VisionPose& /*m*/) {}
  [[nodiscard]] virtual bool uses_vehicle_input() const { return false; }
  virtual void vehicle_input(const msg::VehicleInput& /*m*/) {}

  /// The IMU's group delay as its driver publishes it (`imu_info`, ImuSensorInfo::gyro_delay_s;
  /// `what` describes it). A step whose core compensates a delay takes it unless its
  /// configuration set imu_delay_s (poise/nodes/imu_delay.h); true when the delay in use changed.
  virtual bool published_imu_delay(double /*delay_s*/, const std::string& /*what*/) { return false; }
  /// Which IMU delay the step uses and why; nullptr for a step without one.
  [[nodiscard]] virtual const ImuDelayChoice* imu_delay() const { return nullptr; }

  [[nodiscard]] const std::string& sensor_id() const { return sensor_id_; }
  [[nodiscard]] const std::string& component() const { return component_; }

 private:
  std::string sensor_id_;
  std::string component_;
};

/// An attitude estimator's step: writes AttitudeEstimate (every field the core has) after each
/// accepted sample once the core is initialised, in true ENU when a north is configured.
class AttitudeStep : public EstimatorStep {
 public:
  AttitudeStep(std::string sensor_id, std::string component, NorthReference north = {})
      : EstimatorStep(std::move(sensor_id), std::move(component)), north_(std::move(north)) {}
  [[nodiscard]] unsigned kinds() const override { return kAttitudeOut; }
  bool estimate(const ImuSample& sample, StepOutputs& out) override;

 protected:
  /// The core's attitude (stamp and seq are filled by estimate()); false when it has none.
  virtual bool attitude(AttitudeReport& report) const = 0;
  /// The report last written (for steps that write more, e.g. a pose), in the output frame
  /// (true ENU when a declination is configured).
  [[nodiscard]] const AttitudeReport& last_report() const { return report_; }
  /// North as configured: outputs are rotated into true ENU when north().true_north; the core
  /// works in magnetic ENU throughout.
  [[nodiscard]] const NorthReference& north() const { return north_; }

 private:
  NorthReference north_;
  AttitudeReport report_;
};

using StepFactory = std::function<std::unique_ptr<EstimatorStep>(const runtime::ComponentSpec&)>;

/// The node's shape around a step (the same live and offline). Not thread-safe: the live node
/// serialises calls with its mutex; the malformed counters are atomics a DDS reader may bump.
class StepRunner {
 public:
  using Clock = std::function<int64_t()>;
  /// `clock`: ns in the domain of sample stamps (live: monotonic_ns; offline: the stamp of the
  /// input being processed, so input health is judged on the recording's time).
  StepRunner(std::unique_ptr<EstimatorStep> step, const NodeParams& params, dds::TopicNames topics,
             Clock clock);

  /// One IMU sample from `writer` (an identity of its publisher, for restarts): track, judge its
  /// age (a stale one is counted and not stepped), step, estimate, diagnostics when due
  /// (diagnostics_rate_hz, or every diagnostics_every samples).
  void imu(const ImuSample& sample, const std::string& source, const std::string& writer,
           StepOutputs& out);
  /// Secondary inputs (ignored when the step does not use them; stale ones counted, not passed on).
  void vision(const msg::VisionPose& m, const std::string& writer);
  void vehicle_input(const msg::VehicleInput& m, const std::string& writer);
  /// What an IMU says about itself (`imu_info`): its delay goes to the step with the next sample
  /// of that sensor_id. A delay outside [0, 0.05] s, or a new sensor_id while 256 others' info
  /// waits for their samples, is refused and counted (`imu_info_refused`); returns the refusal's
  /// message ("" when kept).
  std::string imu_info(const msg::ImuSensorInfo& m);
  /// What the node should log once (the step's imu_delay()->describe() after the delay in use
  /// changed; the first sample of an IMU this component does not follow), "" otherwise.
  std::string take_log_message();
  /// The sensor_id of the IMU followed ("" before the first sample when none is configured).
  [[nodiscard]] const std::string& followed_imu() const { return followed_imu_; }
  [[nodiscard]] uint64_t imu_other_sensor() const { return imu_other_sensor_; }
  /// "" when every IMU sample was the followed IMU's; else which one was followed and how many
  /// samples of others were not run.
  [[nodiscard]] std::string other_imu_summary() const;
  /// The periodic diagnostics (the live timer): the core's last report, counters, input health,
  /// when none were published in the last half `diagnostics_period_s` (a silent input); true
  /// when published.
  bool periodic_diagnostics(StepOutputs& out);

  /// Payloads that did not deserialize (the DDS reader or the processor counts them here).
  std::atomic<uint64_t>& imu_malformed() { return imu_malformed_; }
  std::atomic<uint64_t>& vision_malformed() { return vision_malformed_; }
  std::atomic<uint64_t>& vehicle_input_malformed() { return vehicle_input_malformed_; }

  [[nodiscard]] EstimatorStep& step() { return *step_; }
  [[nodiscard]] const EstimatorStep& step() const { return *step_; }
  [[nodiscard]] const NodeParams& params() const { return params_; }
  [[nodiscard]] const dds::TopicNames& topics() const { return topics_; }
  [[nodiscard]] uint64_t received() const { return received_; }
  [[nodiscard]] uint64_t published() const { return published_; }
  [[nodiscard]] uint64_t rejected() const { return rejected_; }
  /// IMU samples older than the input deadline when they arrived (never stepped).
  [[nodiscard]] uint64_t stale() const { return ages_.stale(topics_.imu); }
  [[nodiscard]] uint64_t diagnostics_published() const { return diagnostics_published_; }
  [[nodiscard]] uint64_t vision_received() const { return vision_received_; }
  [[nodiscard]] uint64_t vehicle_inputs_received() const { return vehicle_received_; }
  /// "imu lost N, imu in N, estimates out N, rejected N, malformed N, last latency X us" (", stale
  /// N" after "rejected N" while ages are judged), then
  /// ", vision in N, vision malformed N" / ", vehicle_input in N, vehicle_input malformed N" for
  /// the secondary inputs the step uses; preceded by the silent inputs.
  [[nodiscard]] std::string status() const;

 private:
  void publish_diagnostics(int64_t stamp_ns, uint32_t seq, int64_t now_ns, StepOutputs& out);
  /// Judges a secondary input's age; true when it may be handed to the core.
  bool pass_on(const std::string& topic, const std::string& writer, int64_t stamp_ns, int64_t arrival_ns);

  std::unique_ptr<EstimatorStep> step_;
  NodeParams params_;
  dds::TopicNames topics_;
  Clock clock_;
  uint64_t received_ = 0;
  uint64_t published_ = 0;
  uint64_t rejected_ = 0;
  uint64_t diagnostics_published_ = 0;
  uint64_t vision_received_ = 0;
  uint64_t vehicle_received_ = 0;
  int64_t last_latency_ns_ = 0;
  uint64_t since_diagnostics_ = 0;
  int64_t diagnostics_interval_ns_ = 0;  ///< 1 / diagnostics_rate_hz
  bool diagnostics_sent_ = false;
  int64_t last_diagnostics_ns_ = 0;      ///< clock of the last diagnostics published
  uint32_t last_seq_ = 0;
  InputHealth inputs_;
  /// The last ImuSensorInfo of each sensor_id; its delay is offered to the step at that sensor's
  /// next sample (a node may hear of several IMUs; the step takes the one it is fed).
  std::map<std::string, msg::ImuSensorInfo> imu_infos_;
  /// At most this many sensors' info waits (the QoS profiles' instances per endpoint): more is
  /// refused and counted.
  static constexpr size_t kMaxPendingImuInfos = 256;
  /// false (counted, said once) when `source` is not the IMU this component follows
  bool follows(const std::string& source);
  std::string pending_log_message_;
  std::string followed_imu_;
  uint64_t imu_other_sensor_ = 0;
  bool imu_info_seen_ = false;
  uint64_t imu_info_refused_ = 0;
  InputAge ages_;
  DiagnosticsReport core_report_;  ///< the core's last diagnostics()
  std::atomic<uint64_t> imu_malformed_{0};
  std::atomic<uint64_t> vision_malformed_{0};
  std::atomic<uint64_t> vehicle_input_malformed_{0};
};

}  // namespace poise::nodes
