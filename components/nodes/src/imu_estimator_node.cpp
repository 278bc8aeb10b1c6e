#include "poise/nodes/imu_estimator_node.h"

#include "poise/dds/convert.h"

#include <chrono>
#include <cstdio>
#include <ctime>

namespace poise::nodes {

int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

ImuEstimatorNode::Writers::Writers(runtime::HostContext& host, const EstimatorStep& step)
    : diagnostics_(host.participant, host.topics.diagnostics, dds::QosKind::kEstimate) {
  const unsigned kinds = step.kinds();
  if ((kinds & kAttitudeOut) != 0U) {
    attitude_ = std::make_unique<dds::Writer<msg::AttitudeEstimatePubSubType>>(
        host.participant, host.topics.attitude(step.component()), dds::QosKind::kEstimate);
  }
  if ((kinds & kPoseOut) != 0U) {
    pose_ = std::make_unique<dds::Writer<msg::PoseEstimatePubSubType>>(
        host.participant, host.topics.pose(step.component()), dds::QosKind::kEstimate);
  }
  if ((kinds & kAltitudeOut) != 0U) {
    altitude_ = std::make_unique<dds::Writer<msg::AltitudeEstimatePubSubType>>(
        host.participant, host.topics.altitude, dds::QosKind::kEstimate);
  }
}

// A step writes only the kinds it declared: a missing writer is a defect of the step, not input.
void ImuEstimatorNode::Writers::attitude(const msg::AttitudeEstimate& m) {
  if (attitude_) {
    attitude_->write(m);
  }
}
void ImuEstimatorNode::Writers::pose(const msg::PoseEstimate& m) {
  if (pose_) {
    pose_->write(m);
  }
}
void ImuEstimatorNode::Writers::altitude(const msg::AltitudeEstimate& m) {
  if (altitude_) {
    altitude_->write(m);
  }
}
void ImuEstimatorNode::Writers::diagnostics(const msg::FilterDiagnostics& m) { diagnostics_.write(m); }

ImuEstimatorNode::ImuEstimatorNode(const runtime::ComponentSpec& spec, runtime::HostContext& host,
                                   std::unique_ptr<EstimatorStep> step)
    : host_(host),
      runner_(std::move(step), node_params(spec), host.topics, &monotonic_ns),
      writers_(host, runner_.step()) {}

ImuEstimatorNode::~ImuEstimatorNode() { ImuEstimatorNode::stop(); }

void ImuEstimatorNode::start() {
  running_.store(true);
  if (!imu_info_reader_ && runner_.step().imu_delay() != nullptr) {
    std::fprintf(stderr, "%s %s: %s\n", runner_.step().component().c_str(), runner_.step().sensor_id().c_str(),
                 runner_.step().imu_delay()->describe().c_str());
    // before the samples' reader: a transient-local info is usually there before the first sample
    imu_info_reader_ = std::make_unique<dds::Reader<msg::ImuSensorInfoPubSubType>>(
        host_.participant, host_.topics.imu_info, dds::QosKind::kStatic,
        [this](const msg::ImuSensorInfo& m, const auto& /*info*/) {
          std::lock_guard<std::mutex> lock(mutex_);
          const std::string problem = runner_.imu_info(m);
          if (!problem.empty()) {
            std::fprintf(stderr, "%s %s: %s\n", runner_.step().component().c_str(),
                         runner_.step().sensor_id().c_str(), problem.c_str());
          }
        },
        &imu_info_malformed_);
  }
  if (!imu_reader_) {
    imu_reader_ = std::make_unique<dds::Reader<msg::ImuSamplePubSubType>>(
        host_.participant, host_.topics.imu, dds::QosKind::kSensor,
        [this](const msg::ImuSample& m, const auto& info) { on_imu(m, info); },
        &runner_.imu_malformed());
  }
  if (!vision_reader_ && runner_.step().uses_vision()) {
    vision_reader_ = std::make_unique<dds::Reader<msg::VisionPosePubSubType>>(
        host_.participant, host_.topics.vision_pose, dds::QosKind::kEstimate,
        [this](const msg::VisionPose& m, const auto& info) {
          std::lock_guard<std::mutex> lock(mutex_);
          runner_.vision(m, dds::writer_key(info));
        },
        &runner_.vision_malformed());
  }
  if (!vehicle_reader_ && runner_.step().uses_vehicle_input()) {
    vehicle_reader_ = std::make_unique<dds::Reader<msg::VehicleInputPubSubType>>(
        host_.participant, host_.topics.vehicle_input, dds::QosKind::kSensor,
        [this](const msg::VehicleInput& m, const auto& info) {
          std::lock_guard<std::mutex> lock(mutex_);
          runner_.vehicle_input(m, dds::writer_key(info));
        },
        &runner_.vehicle_input_malformed());
  }
  if (!timer_.joinable()) {
    {
      std::lock_guard<std::mutex> lock(timer_mutex_);
      timer_stop_ = false;
    }
    timer_ = std::thread([this] { run_timer(); });
  }
}

void ImuEstimatorNode::stop() {
  running_.store(false);
  // no callback runs after a reader is reset
  vision_reader_.reset();
  vehicle_reader_.reset();
  imu_reader_.reset();
  imu_info_reader_.reset();
  {
    std::lock_guard<std::mutex> lock(timer_mutex_);
    timer_stop_ = true;
  }
  timer_cv_.notify_all();
  if (timer_.joinable()) {
    timer_.join();
  }
}

void ImuEstimatorNode::run_timer() {
  const auto period = std::chrono::duration<double>(runner_.params().diagnostics_period_s);
  std::unique_lock<std::mutex> timer_lock(timer_mutex_);
  while (!timer_cv_.wait_for(timer_lock, period, [this] { return timer_stop_; })) {
    std::lock_guard<std::mutex> lock(mutex_);
    runner_.periodic_diagnostics(writers_);
  }
}

void ImuEstimatorNode::on_imu(const msg::ImuSample& m, const eprosima::fastdds::dds::SampleInfo& info) {
  if (!running_.load()) {
    return;
  }
  const ImuSample sample = dds::from_msg(m);
  std::lock_guard<std::mutex> lock(mutex_);
  runner_.imu(sample, m.sensor_id().to_string(), dds::writer_key(info), writers_);
  const std::string said = runner_.take_log_message();
  if (!said.empty()) {
    std::fprintf(stderr, "%s %s: %s\n", runner_.step().component().c_str(), runner_.step().sensor_id().c_str(),
                 said.c_str());
  }
}

std::string ImuEstimatorNode::status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return runner_.status();
}

std::optional<uint64_t> ImuEstimatorNode::produced() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return runner_.published();
}

runtime::ComponentType estimator_component(const std::string& type, const std::string& description,
                                           StepFactory make) {
  return {type, description,
          [make](const runtime::ComponentSpec& spec, runtime::HostContext& host) {
            return std::make_unique<ImuEstimatorNode>(spec, host, make(spec));
          }};
}

}  // namespace poise::nodes
