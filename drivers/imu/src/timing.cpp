#include "poise/imu/timing.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace poise::imu {

SequenceTracker::Verdict SequenceTracker::check(uint32_t seq, uint32_t* gap) const {
  *gap = 0;
  if (!has_last_) return Verdict::kFirst;
  const uint32_t forward = seq - last_;  // modular distance
  if (forward == 0) return Verdict::kDuplicate;
  const uint32_t backward = last_ - seq;
  if (backward <= params_.reorder_window) return Verdict::kOutOfOrder;
  if (forward - 1 > params_.max_forward_gap) return Verdict::kRestart;
  *gap = forward - 1;
  return Verdict::kNext;
}

int64_t TimeUnwrapper::peek_ns(uint32_t t_us) const {
  if (!has_last_) return static_cast<int64_t>(t_us) * 1000;
  const auto step = static_cast<int32_t>(t_us - last_);  // two's complement: signed 31-bit step
  return (last_us_ + step) * 1000;
}

void TimeUnwrapper::commit(uint32_t t_us) {
  if (has_last_) {
    last_us_ += static_cast<int32_t>(t_us - last_);
  } else {
    last_us_ = t_us;
    has_last_ = true;
  }
  last_ = t_us;
}

bool ClockJumpAnchor::refused(uint32_t seq, uint32_t t_us) {
  const uint32_t dseq = seq - last_seq_;   // modular: both counters wrap
  const uint32_t dt_us = t_us - last_t_us_;
  const bool agrees = run_ > 0 && dseq >= 1 && dseq <= max_seq_step_ && dt_us > 0 &&
                      static_cast<double>(dt_us) <= max_step_us_ * static_cast<double>(dseq);
  run_ = agrees ? run_ + 1 : 1;
  last_seq_ = seq;
  last_t_us_ = t_us;
  if (run_ >= samples_) {
    run_ = 0;
    return true;
  }
  return false;
}

ClockSync::ClockSync(const ClockSyncParams& p) : params_(p) {
  params_.window_blocks = std::max(params_.window_blocks, 2);
}

void ClockSync::reset() {
  initialized_ = false;
  blocks_.clear();
  has_current_ = false;
  slope_ = 0;
  intercept_ = 0;
}

void ClockSync::refit() {
  // Points: completed block minima plus the running minimum of the current block.
  std::vector<Point> pts(blocks_.begin(), blocks_.end());
  if (has_current_) pts.push_back(current_);
  if (pts.size() == 1) {
    slope_ = 0;
    intercept_ = pts[0].d;
    return;
  }
  // Lower convex hull (Andrew's monotone chain; points are sorted by t).
  std::vector<Point> hull;
  for (const Point& p : pts) {
    while (hull.size() >= 2) {
      const Point& a = hull[hull.size() - 2];
      const Point& b = hull[hull.size() - 1];
      const double cross = (b.t - a.t) * (p.d - a.d) - (b.d - a.d) * (p.t - a.t);
      if (cross <= 0) {
        hull.pop_back();
      } else {
        break;
      }
    }
    hull.push_back(p);
  }
  double mean_t = 0;
  for (const Point& p : pts) mean_t += p.t;
  mean_t /= static_cast<double>(pts.size());
  double slope = 0;
  for (std::size_t i = 0; i + 1 < hull.size(); ++i) {
    if (hull[i + 1].t >= mean_t || i + 2 == hull.size()) {
      slope = (hull[i + 1].d - hull[i].d) / (hull[i + 1].t - hull[i].t);
      break;
    }
  }
  const double max_slope = params_.max_drift_ppm * 1e-6;
  slope_ = std::clamp(slope, -max_slope, max_slope);
  // The supporting line with this slope touches the lowest point.
  double icpt = pts[0].d - slope_ * pts[0].t;
  for (const Point& p : pts) icpt = std::min(icpt, p.d - slope_ * p.t);
  intercept_ = icpt;
}

int64_t ClockSync::update(int64_t sensor_ns, int64_t arrival_ns) {
  if (!initialized_) {
    t0_ = sensor_ns;
    d0_ = arrival_ns - sensor_ns;
    blocks_.clear();
    has_current_ = false;
    initialized_ = true;
  }
  const Point p{static_cast<double>(sensor_ns - t0_),
                static_cast<double>((arrival_ns - sensor_ns) - d0_)};
  const double threshold_ns = params_.reset_threshold_s * 1e9;
  const double block_ns = params_.block_s * 1e9;
  const bool have_line = has_current_ || !blocks_.empty();
  if (have_line && (p.d < envelope(p.t) - threshold_ns || p.t < block_start_ - threshold_ns)) {
    // The sensor clock jumped relative to the host clock: start over.
    ++resets_;
    reset();
    return update(sensor_ns, arrival_ns);
  }
  if (!has_current_) {
    current_ = p;
    block_start_ = p.t;
    has_current_ = true;
  } else if (p.t - block_start_ >= block_ns) {
    if (!blocks_.empty() && current_.d > envelope(current_.t) + threshold_ns) {
      // A whole block far above the envelope: the sensor clock went backwards. Restart.
      ++resets_;
      reset();
      return update(sensor_ns, arrival_ns);
    }
    blocks_.push_back(current_);
    while (blocks_.size() > static_cast<std::size_t>(params_.window_blocks)) blocks_.pop_front();
    current_ = p;
    block_start_ = p.t;
  } else if (p.d < current_.d) {
    current_ = p;
  }
  refit();
  const double offset = static_cast<double>(d0_) + envelope(p.t);
  int64_t stamp = sensor_ns + static_cast<int64_t>(std::llround(offset));
  stamp = std::min(stamp, arrival_ns);
  if (has_stamp_ && stamp <= last_stamp_) stamp = last_stamp_ + 1;  // strictly increasing
  last_stamp_ = stamp;
  has_stamp_ = true;
  last_offset_ns_ = stamp - sensor_ns;
  return stamp;
}

}  // namespace poise::imu
