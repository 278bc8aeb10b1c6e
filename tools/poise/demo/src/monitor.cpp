#include "poise/demo/monitor.h"

#include "poise/core/attitude.h"
#include "poise/dds/convert.h"
#include "poise/nodes/imu_estimator_node.h"
#include "poise/simulated/sim_imu.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace poise::demo {

double percentile(std::vector<double> values, double p) {
  if (values.empty()) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  const auto k = static_cast<std::size_t>(std::clamp(p / 100.0, 0.0, 1.0) * static_cast<double>(values.size() - 1));
  std::nth_element(values.begin(), values.begin() + static_cast<long>(k), values.end());
  return values[k];
}

struct PipelineMonitor::Impl {
  using AttitudeReader = dds::Reader<msg::AttitudeEstimatePubSubType>;
  mutable std::mutex mutex;
  int64_t start_ns = nodes::monotonic_ns();
  std::map<std::string, FilterStats> stats;
  std::map<std::string, std::vector<AttitudePoint>> series;
  std::map<std::string, std::vector<std::pair<double, double>>> errors;
  std::map<std::string, std::map<uint32_t, double>> errors_by_seq;
  std::map<uint32_t, Eigen::Quaterniond> truth_by_seq;  // recent truth, for matching
  struct Estimate {
    Eigen::Quaterniond q;
    Eigen::Matrix3d cov;  // published attitude_covariance, rad^2
  };
  std::map<std::string, std::map<uint32_t, Estimate>> pending;  // estimates before truth
  std::map<std::string, std::vector<AltitudePoint>> altitude;
  std::map<std::string, std::vector<PositionPoint>> positions;
  std::map<std::string, std::vector<std::pair<double, double>>> position_errors;
  std::map<uint32_t, Eigen::Vector3d> truth_position_by_seq;  // recent truth, for matching
  std::map<std::string, std::map<uint32_t, PositionPoint>> pending_positions;  // before their truth
  std::vector<std::unique_ptr<dds::Reader<msg::PoseEstimatePubSubType>>> pose_readers;
  CameraStats camera;
  std::map<std::string, uint64_t> rejected;
  std::vector<std::unique_ptr<AttitudeReader>> attitude_readers;
  std::unique_ptr<dds::Reader<msg::AltitudeEstimatePubSubType>> altitude_reader;
  std::unique_ptr<dds::Reader<msg::AltitudeEstimatePubSubType>> altitude_truth_reader;
  std::unique_ptr<dds::Reader<msg::TagDetectionsPubSubType>> tags_reader;
  std::unique_ptr<dds::Reader<msg::VisionPosePubSubType>> vision_reader;
  std::unique_ptr<dds::Reader<msg::FilterDiagnosticsPubSubType>> diagnostics_reader;

  [[nodiscard]] double now_s() const { return static_cast<double>(nodes::monotonic_ns() - start_ns) * 1e-9; }

  void compare(const std::string& filter, uint32_t seq, const Estimate& est, double t_s) {
    const auto it = truth_by_seq.find(seq);
    if (it == truth_by_seq.end()) {
      pending[filter][seq] = est;
      return;
    }
    const double e = quat_angle_between(est.q, it->second) * 180.0 / M_PI;
    FilterStats& s = stats[filter];
    s.nees.add(attitude_nees(world_attitude_error(est.q, it->second), est.cov));
    s.error_deg = e;
    s.sum_sq_error += e * e;
    ++s.compared;
    errors[filter].emplace_back(t_s, e);
    errors_by_seq[filter][seq] = e;
  }

  void on_pose(const std::string& filter, const msg::PoseEstimate& m) {
    PositionPoint p;
    p.t_s = now_s();
    p.seq = m.header().seq();
    p.p_m = dds::from_msg(m.position_m());
    std::lock_guard<std::mutex> lock(mutex);
    positions[filter].push_back(p);
    if (filter != "truth") {
      const auto it = truth_position_by_seq.find(p.seq);
      if (it == truth_position_by_seq.end()) {
        auto& waiting = pending_positions[filter];
        waiting[p.seq] = p;
        while (waiting.size() > 2000) {
          waiting.erase(waiting.begin());
        }
        return;
      }
      position_errors[filter].emplace_back(p.t_s, (p.p_m - it->second).norm());
      return;
    }
    truth_position_by_seq[p.seq] = p.p_m;
    while (truth_position_by_seq.size() > 4000) {
      truth_position_by_seq.erase(truth_position_by_seq.begin());
    }
    for (auto& [name, waiting] : pending_positions) {  // estimates that arrived before their truth
      const auto w = waiting.find(p.seq);
      if (w != waiting.end()) {
        position_errors[name].emplace_back(w->second.t_s, (w->second.p_m - p.p_m).norm());
        waiting.erase(w);
      }
    }
  }

  void on_attitude(const std::string& filter, const msg::AttitudeEstimate& m) {
    const double t = now_s();
    AttitudePoint p;
    p.t_s = t;
    p.stamp_ns = m.header().stamp_ns();
    p.q = dds::from_msg(m.q_world_body());
    p.rpy_rad = {m.roll_rad(), m.pitch_rad(), m.yaw_rad()};
    p.disturbance_norm_ut = m.mag_disturbance_norm_ut();
    p.mag_trusted = m.mag_trusted();
    p.latency_ms = static_cast<double>(nodes::monotonic_ns() - p.stamp_ns) * 1e-6;
    std::lock_guard<std::mutex> lock(mutex);
    series[filter].push_back(p);
    FilterStats& s = stats[filter];
    ++s.received;
    s.latest = p;
    s.rate_hz = s.received / std::max(1e-3, t);
    if (filter == "truth") {
      const uint32_t seq = m.header().seq();
      truth_by_seq[seq] = p.q;
      while (truth_by_seq.size() > 4000) {
        truth_by_seq.erase(truth_by_seq.begin());
      }
      for (auto& [name, waiting] : pending) {  // estimates that arrived before their truth
        const auto w = waiting.find(seq);
        if (w != waiting.end()) {
          const Estimate est = w->second;
          waiting.erase(w);
          compare(name, seq, est, t);
        }
        while (waiting.size() > 2000) {
          waiting.erase(waiting.begin());
        }
      }
      return;
    }
    if (s.latencies_ms.size() < 200000) {
      s.latencies_ms.push_back(p.latency_ms);
    }
    Estimate est{p.q, Eigen::Matrix3d::Zero()};
    for (int k = 0; k < 9; ++k) {
      est.cov(k / 3, k % 3) = m.attitude_covariance()[static_cast<size_t>(k)];
    }
    compare(filter, m.header().seq(), est, t);
  }
};

PipelineMonitor::PipelineMonitor(dds::Participant& participant, const dds::TopicNames& topics,
                                 const std::vector<std::string>& filters)
    : impl_(std::make_unique<Impl>()) {
  Impl* impl = impl_.get();
  std::vector<std::pair<std::string, std::string>> subscriptions{{"truth", simulated::kTruthAttitudeTopic}};
  for (const auto& f : filters) {
    subscriptions.emplace_back(f, topics.attitude(f));
  }
  for (const auto& [name, topic] : subscriptions) {
    const std::string filter = name;
    impl->attitude_readers.push_back(std::make_unique<Impl::AttitudeReader>(
        participant, topic, dds::QosKind::kEstimate,
        [impl, filter](const msg::AttitudeEstimate& m, const auto&) { impl->on_attitude(filter, m); }));
  }
  std::vector<std::pair<std::string, std::string>> pose_subscriptions{{"truth", simulated::kTruthPoseTopic}};
  for (const auto& f : filters) {
    pose_subscriptions.emplace_back(f, topics.pose(f));  // only the filters that publish a pose send any
  }
  for (const auto& [name, topic] : pose_subscriptions) {
    const std::string filter = name;
    impl->pose_readers.push_back(std::make_unique<dds::Reader<msg::PoseEstimatePubSubType>>(
        participant, topic, dds::QosKind::kEstimate,
        [impl, filter](const msg::PoseEstimate& m, const auto&) { impl->on_pose(filter, m); }));
  }
  auto on_altitude = [impl](const std::string& key) {
    return [impl, key](const msg::AltitudeEstimate& m, const auto&) {
      AltitudePoint p;
      p.t_s = impl->now_s();
      p.seq = m.header().seq();
      p.height_m = m.height_m();
      p.vertical_velocity_mps = m.vertical_velocity_mps();
      p.baro_height_m = m.baro_valid() ? m.baro_height_m() : std::numeric_limits<double>::quiet_NaN();
      p.stationary = m.stationary();
      std::lock_guard<std::mutex> lock(impl->mutex);
      impl->altitude[key].push_back(p);
    };
  };
  impl->altitude_reader = std::make_unique<dds::Reader<msg::AltitudeEstimatePubSubType>>(
      participant, topics.altitude, dds::QosKind::kEstimate, on_altitude("altitude"));
  impl->altitude_truth_reader = std::make_unique<dds::Reader<msg::AltitudeEstimatePubSubType>>(
      participant, simulated::kTruthAltitudeTopic, dds::QosKind::kEstimate, on_altitude("truth"));
  impl->tags_reader = std::make_unique<dds::Reader<msg::TagDetectionsPubSubType>>(
      participant, topics.tag_detections, dds::QosKind::kSensor,
      [impl](const msg::TagDetections& m, const auto&) {
        std::lock_guard<std::mutex> lock(impl->mutex);
        ++impl->camera.frames;
        impl->camera.tags_in_view = static_cast<int>(m.detections().size());
        impl->camera.tags_series.emplace_back(impl->now_s(), impl->camera.tags_in_view);
      });
  impl->vision_reader = std::make_unique<dds::Reader<msg::VisionPosePubSubType>>(
      participant, topics.vision_pose, dds::QosKind::kEstimate,
      [impl](const msg::VisionPose&, const auto&) {
        std::lock_guard<std::mutex> lock(impl->mutex);
        ++impl->camera.poses;
        impl->camera.last_pose_t_s = impl->now_s();
      });
  impl->diagnostics_reader = std::make_unique<dds::Reader<msg::FilterDiagnosticsPubSubType>>(
      participant, topics.diagnostics, dds::QosKind::kEstimate,
      [impl](const msg::FilterDiagnostics& m, const auto&) {
        uint64_t total = 0;
        for (const auto& c : m.counters()) {
          const std::string n = c.name().to_string();
          if (n.rfind("rejected", 0) == 0 || n.rfind("non_", 0) == 0 || n.rfind("zero_", 0) == 0 ||
              n.rfind("missing_", 0) == 0 || n == "time_gap" ||
              n.find("_out_of_range") != std::string::npos) {
            total += c.value();
          }
        }
        std::lock_guard<std::mutex> lock(impl->mutex);
        impl->rejected[m.component_name().to_string()] = total;
      });
}

PipelineMonitor::~PipelineMonitor() = default;

std::map<std::string, FilterStats> PipelineMonitor::filter_stats() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->stats;
}

std::map<std::string, std::vector<AttitudePoint>> PipelineMonitor::attitude_series() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->series;
}

std::map<std::string, std::vector<AltitudePoint>> PipelineMonitor::altitude_series() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->altitude;
}

std::map<std::string, std::vector<std::pair<double, double>>> PipelineMonitor::error_series() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->errors;
}

std::map<std::string, std::map<uint32_t, double>> PipelineMonitor::errors_by_seq() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->errors_by_seq;
}

std::map<std::string, std::vector<PositionPoint>> PipelineMonitor::position_series() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->positions;
}

std::map<std::string, std::vector<std::pair<double, double>>> PipelineMonitor::position_errors() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->position_errors;
}

PipelineMonitor::CameraStats PipelineMonitor::camera_stats() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->camera;
}

std::map<std::string, uint64_t> PipelineMonitor::rejected_counts() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->rejected;
}

double PipelineMonitor::elapsed_s() const { return impl_->now_s(); }

}  // namespace poise::demo
