// AttitudeFilter: the small interface every attitude estimator offers to evaluation and
// benchmarking (`poise eval broad`, `poise bench filters`). Filters implement it in an adapter
// beside their own class; the eval library keeps a table of named factories that other
// libraries extend (see poise/eval/filter_registry.h).
#pragma once

#include "poise/core/heading_status.h"
#include "poise/core/source_report.h"
#include "poise/core/types.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <map>
#include <optional>
#include <string>

namespace poise {

class AttitudeFilter {
 public:
  virtual ~AttitudeFilter() = default;
  /// Feeds one IMU sample (stamps must increase). Returns false when the sample was rejected
  /// (bad data); the state is then untouched and the rejection counted.
  virtual bool update(const ImuSample& sample) = 0;
  /// Current attitude, q_world_body, world ENU (identity until initialised).
  [[nodiscard]] virtual Eigen::Quaterniond q_world_body() const = 0;
  [[nodiscard]] virtual bool initialized() const = 0;
  /// Back to the state before the first sample (parameters kept).
  virtual void reset() = 0;
  /// Rejection counters by reason (for reports); empty when the filter keeps none.
  [[nodiscard]] virtual std::map<std::string, uint64_t> rejections() const { return {}; }
  /// Seeds the start-up magnetic field reference (|B| uT, dip deg below the horizontal, e.g.
  /// from the World Magnetic Model at the recording's location) where the filter's own is not
  /// configured (NaN); a NaN argument changes nothing. Call before the first sample; the filter
  /// starts again. Filters without a field reference ignore it.
  virtual void seed_field(double /*field_ut*/, double /*dip_deg*/) {}
  /// The covariance the filter publishes with q_world_body(): of the world-frame rotation vector
  /// e of q_true (x) q_est^-1 (rad^2, about ENU x, y, z; the IDL's attitude_covariance). Empty
  /// when the filter has none (or is not initialised): a consumer then reads "unknown", never 0.
  [[nodiscard]] virtual std::optional<Eigen::Matrix3d> attitude_covariance() const { return std::nullopt; }
  /// Whether the heading is backed by a field the filter trusts (poise/core/heading_status.h):
  /// kUnverified during a cold start whose field reference is not yet verified or a long gated
  /// stretch (the heading part of attitude_covariance() then says how far it may be off),
  /// kNoReference for filters without an absolute heading (the default).
  [[nodiscard]] virtual HeadingStatus heading_status() const { return HeadingStatus::kNoReference; }
  /// What the last sample did with each input and why (poise/core/source_report.h): the same
  /// reports the filter's node publishes, so an offline run (`poise process --filter`) says
  /// which sources it fused as the live node does. Empty when the filter keeps none.
  [[nodiscard]] virtual SourceReports sources() const { return {}; }
  /// The group delay the IMU's driver published for the samples (`imu_info`), s: a filter whose
  /// configuration did not set its delay uses it from the next sample on. True when it does;
  /// false when the filter has no delay model or its configuration set the delay (it wins).
  virtual bool take_published_imu_delay(double /*delay_s*/) { return false; }
};

}  // namespace poise
