#include "poise/nodes/reports.h"

#include "poise/core/attitude.h"
#include "poise/dds/convert.h"

#include <algorithm>

namespace poise::nodes {
namespace {
constexpr std::size_t kMaxSources = 16;   // bounds of msg::FilterDiagnostics (diagnostics.idl)
constexpr std::size_t kMaxCounters = 64;
constexpr std::size_t kMaxMetrics = 32;
constexpr std::size_t kMaxInnovation = 6;
}  // namespace

uint32_t source_bit(Source s) {
  switch (s) {  // no default: a new Source does not compile (-Werror=switch) until it has a bit
    case Source::kGyro:
    case Source::kYawRate: return msg::SOURCE_GYRO;
    case Source::kAccel:
    case Source::kAccelTilt: return msg::SOURCE_ACCEL;
    case Source::kMag:
    case Source::kMagHeading: return msg::SOURCE_MAG;
    case Source::kImuQuat: return msg::SOURCE_IMU_QUAT;
    case Source::kVisionAttitude:
    case Source::kVisionPosition: return msg::SOURCE_VISION;
    case Source::kBaro: return msg::SOURCE_BARO;
    case Source::kSpeed: return msg::SOURCE_SPEED;
    case Source::kZupt:      // pseudo-measurements of a rest detector: no sensor of their own
    case Source::kZeroRate:
    case Source::kCount: return 0;
  }
  return 0;
}

uint32_t sources_fused_bits(const SourceReports& sources) {
  uint32_t bits = 0;
  for (const SourceReport& s : sources) {
    if (s.fused()) {
      bits |= source_bit(s.source);
    }
  }
  return bits;
}

bool source_fused(const SourceReports& sources, Source source) {
  return std::any_of(sources.begin(), sources.end(),
                     [source](const SourceReport& s) { return s.source == source && s.fused(); });
}

HeadingStatus heading_status_from_mag(const SourceReports& sources) {
  for (const SourceReport& s : sources) {
    if (s.source == Source::kMag) {
      if (s.fused()) {
        return HeadingStatus::kVerified;
      }
      if (s.decision == SourceDecision::kRejected) {
        return HeadingStatus::kUnverified;
      }
    }
  }
  return HeadingStatus::kNoReference;
}

msg::HeadingStatus to_msg(HeadingStatus status) {
  switch (status) {  // no default: a new status fails to compile until it is mapped
    case HeadingStatus::kNoReference: return msg::HEADING_NO_REFERENCE;
    case HeadingStatus::kVerified: return msg::HEADING_VERIFIED;
    case HeadingStatus::kUnverified: return msg::HEADING_UNVERIFIED;
  }
  return msg::HEADING_NO_REFERENCE;
}

msg::AttitudeEstimate to_attitude_msg(const AttitudeReport& r, const std::string& sensor_id,
                                      const std::string& filter_id) {
  msg::AttitudeEstimate m;
  m.header(dds::make_header(r.stamp_ns, r.seq, r.frame_id));
  m.sensor_id(sensor_id);
  m.filter_id(filter_id);
  const Eigen::Quaterniond q = r.q_world_body.normalized();
  m.q_world_body(dds::to_msg(q));
  const Eigen::Vector3d rpy = euler_zyx_from_quat(q);  // roll, pitch, yaw
  m.roll_rad(rpy.x());
  m.pitch_rad(rpy.y());
  m.yaw_rad(rpy.z());
  dds::to_array(r.covariance, m.attitude_covariance());
  m.ext_accel_body_mps2(dds::to_msg(r.ext_accel_body_mps2));
  m.ext_accel_world_mps2(dds::to_msg(r.ext_accel_world_mps2));
  m.mag_disturbance_body_ut(dds::to_msg(r.mag_disturbance_body_ut));
  m.mag_disturbance_world_ut(dds::to_msg(r.mag_disturbance_world_ut));
  m.mag_disturbance_norm_ut(r.mag_disturbance_world_ut.norm());
  m.mag_disturbance_angle_rad(r.mag_disturbance_angle_rad);
  m.mag_trusted(r.mag_trusted);
  m.sources_fused(r.sources_fused);
  m.gyro_bias_rps(dds::to_msg(r.gyro_bias_rps));
  m.heading_status(to_msg(r.heading_status));
  return m;
}

msg::FilterDiagnostics to_diagnostics_msg(const DiagnosticsReport& r, const std::string& sensor_id) {
  msg::FilterDiagnostics m;
  m.header(dds::make_header(r.stamp_ns, r.seq, "body"));
  m.sensor_id(sensor_id);
  m.component_name(r.component);
  uint64_t truncated = 0;
  for (const auto& s : r.sources) {
    if (m.sources().size() >= kMaxSources) {
      ++truncated;
      continue;
    }
    msg::SourceStatus status;
    status.source(to_string(s.source));
    status.fresh(s.decision != SourceDecision::kNotAvailable);
    status.fused(s.fused());
    status.reason(*s.reason == '\0' && !s.fused() ? to_string(s.decision) : s.reason);
    const auto size = static_cast<std::size_t>(s.innovation.size());
    const auto size_var = static_cast<std::size_t>(s.innovation_variance.size());
    const std::size_t n = std::min(size, kMaxInnovation);
    const std::size_t nv = std::min(size_var, kMaxInnovation);
    truncated += (size - n) + (size_var - nv);
    status.innovation(std::vector<double>(s.innovation.data(), s.innovation.data() + n));
    status.innovation_variance(
        std::vector<double>(s.innovation_variance.data(), s.innovation_variance.data() + nv));
    status.test_ratio(s.test_ratio);
    status.last_fused_stamp_ns(std::max<int64_t>(0, s.last_fused_stamp_ns));
    status.fused_count(s.fused_count);
    status.rejected_count(s.rejected_count);
    m.sources().push_back(status);
  }
  for (const auto& mr : r.metrics) {
    if (m.metrics().size() >= kMaxMetrics) {
      ++truncated;
      continue;
    }
    msg::Metric metric;
    metric.name(mr.name);
    metric.value(mr.value);
    metric.unit(mr.unit);
    m.metrics().push_back(metric);
  }
  auto add_counter = [&m](const std::string& name, uint64_t value) {
    msg::Counter c;
    c.name(name);
    c.value(value);
    m.counters().push_back(c);
  };
  for (const auto& [name, value] : r.counters) {
    if (m.counters().size() >= kMaxCounters - 1) {  // keep one slot for the truncation counter
      ++truncated;
      continue;
    }
    add_counter(name, value);
  }
  if (truncated != 0) {
    add_counter("diagnostics_truncated", truncated);
  }
  return m;
}

}  // namespace poise::nodes
