// A host running one estimator component on its own domain, fed over DDS by the test, with the
// diagnostics and estimates it publishes collected by seq (loopback, bounded waits).
#pragma once

#include "poise/core/source_report.h"
#include "poise/dds/convert.h"
#include "poise/runtime/host.h"
#include "poise/testing/testing.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <map>
#include <mutex>
#include <optional>
#include <string>

namespace poise::runtime {
void register_estimator_nodes(ComponentRegistry& registry);
}

namespace poise::testing {

class NodeHarness {
 public:
  /// `component_yaml`: one host-file component entry, e.g. "{type: vehicle, name: veh}".
  explicit NodeHarness(const std::string& component_yaml, const std::string& attitude_topic = "")
      : host_(make_spec(component_yaml), domain_.id()), participant_({domain_.id(), "", "", "test"}) {
    host_.start();
    diagnostics_ = std::make_unique<dds::Reader<msg::FilterDiagnosticsPubSubType>>(
        participant_, "diagnostics", [this](const msg::FilterDiagnostics& m, const auto&) {
          std::lock_guard<std::mutex> lock(mutex_);
          diagnostics_by_seq_[m.header().seq()] = m;
        });
    if (!attitude_topic.empty()) {
      attitude_ = std::make_unique<dds::Reader<msg::AttitudeEstimatePubSubType>>(
          participant_, attitude_topic, [this](const msg::AttitudeEstimate& m, const auto&) {
            std::lock_guard<std::mutex> lock(mutex_);
            attitude_by_seq_[m.header().seq()] = m;
          });
    }
    imu_ = std::make_unique<dds::Writer<msg::ImuSamplePubSubType>>(participant_, "imu", dds::QosKind::kEstimate);
  }
  ~NodeHarness() { host_.stop(); }

  /// Waits for the node's imu reader; false after 10 s.
  bool connected() {
    using namespace std::chrono_literals;
    return imu_->wait_for_readers(1, 10s) && diagnostics_->wait_for_writers(1, 10s);
  }
  dds::Participant& participant() { return participant_; }

  /// Publishes one IMU sample, paced like a 1 kHz sensor (the node's input is best-effort).
  void publish(const ImuSample& s) {
    imu_->write(dds::to_msg(s, "sim"));
    sleep_ms(1);
  }

  /// The diagnostics published for the newest seq >= `min_seq` (waits up to 10 s for one).
  std::optional<msg::FilterDiagnostics> diagnostics_from(uint32_t min_seq) {
    using namespace std::chrono_literals;
    std::optional<msg::FilterDiagnostics> out;
    wait_until([&] {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto it = diagnostics_by_seq_.lower_bound(min_seq);
      if (it != diagnostics_by_seq_.end()) {
        out = diagnostics_by_seq_.rbegin()->second;
      }
      return out.has_value();
    }, 10s);
    return out;
  }
  std::optional<msg::AttitudeEstimate> attitude(uint32_t seq) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = attitude_by_seq_.find(seq);
    return it == attitude_by_seq_.end() ? std::nullopt : std::optional<msg::AttitudeEstimate>(it->second);
  }
  std::size_t attitude_count() {
    std::lock_guard<std::mutex> lock(mutex_);
    return attitude_by_seq_.size();
  }

 private:
  static runtime::HostSpec make_spec(const std::string& component_yaml) {
    auto& registry = runtime::ComponentRegistry::instance();
    if (registry.find("parallel_kf") == nullptr) {
      runtime::register_estimator_nodes(registry);
    }
    return runtime::parse_host(YAML::Load("components: [" + component_yaml + "]"), "test", ".");
  }

  DomainLease domain_;
  runtime::Host host_;
  dds::Participant participant_;
  std::mutex mutex_;
  std::map<uint32_t, msg::FilterDiagnostics> diagnostics_by_seq_;
  std::map<uint32_t, msg::AttitudeEstimate> attitude_by_seq_;
  std::unique_ptr<dds::Reader<msg::FilterDiagnosticsPubSubType>> diagnostics_;
  std::unique_ptr<dds::Reader<msg::AttitudeEstimatePubSubType>> attitude_;
  std::unique_ptr<dds::Writer<msg::ImuSamplePubSubType>> imu_;
};

/// The published status of `source` (fails the test when it is missing).
inline msg::SourceStatus published_source(const msg::FilterDiagnostics& d, const std::string& source) {
  for (const auto& s : d.sources()) {
    if (s.source() == source) {
      return s;
    }
  }
  ADD_FAILURE() << "diagnostics of " << d.component_name() << " carry no source '" << source << "'";
  return {};
}

/// The published counter `name` (0 when absent).
inline uint64_t published_counter(const msg::FilterDiagnostics& d, const std::string& name) {
  for (const auto& c : d.counters()) {
    if (c.name() == name) {
      return c.value();
    }
  }
  return 0;
}

/// The published status agrees with the core's report of the same step.
inline void expect_same_decision(const msg::SourceStatus& published, const SourceReport& core) {
  EXPECT_EQ(published.source(), to_string(core.source));
  EXPECT_EQ(published.fresh(), core.decision != SourceDecision::kNotAvailable) << to_string(core.source);
  EXPECT_EQ(published.fused(), core.fused()) << to_string(core.source);
  if (*core.reason != '\0') {
    EXPECT_EQ(published.reason(), core.reason) << to_string(core.source);
  }
}

/// A sample at rest, body = world (ENU), 100 Hz stamps from 1 s.
inline ImuSample rest_sample(uint32_t seq) {
  ImuSample s;
  s.seq = seq;
  s.stamp_ns = 1'000'000'000 + static_cast<int64_t>(seq) * 10'000'000;
  s.accel_mps2 = Eigen::Vector3d(0.0, 0.0, 9.81);
  s.gyro_rps.setZero();
  s.mag_ut = Eigen::Vector3d(0.0, 20.0, -40.0);  // north and down (dip ~63 deg)
  s.has_mag = true;
  return s;
}

}  // namespace poise::testing
