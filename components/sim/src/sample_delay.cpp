#include "poise/sim/sample_delay.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace poise::sim {
namespace {

/// The value of `field` at time t_ns, linearly interpolated over `history` (held before it).
template <typename Field>
Eigen::Vector3d at_time(const std::deque<ImuSample>& history, int64_t t_ns, Field field) {
  if (t_ns <= history.front().stamp_ns) {
    return field(history.front());
  }
  for (std::size_t i = history.size() - 1; i > 0; --i) {
    const ImuSample& a = history[i - 1];
    const ImuSample& b = history[i];
    if (a.stamp_ns <= t_ns && t_ns <= b.stamp_ns) {
      const double span = static_cast<double>(b.stamp_ns - a.stamp_ns);
      const double w = span > 0 ? static_cast<double>(t_ns - a.stamp_ns) / span : 1.0;
      return (1.0 - w) * field(a) + w * field(b);
    }
  }
  return field(history.back());
}

}  // namespace

SampleDelay::SampleDelay(double accel_delay_s, double gyro_delay_s)
    : accel_delay_s_(accel_delay_s), gyro_delay_s_(gyro_delay_s) {
  if (!(accel_delay_s >= 0.0 && gyro_delay_s >= 0.0 && accel_delay_s < 1.0 && gyro_delay_s < 1.0)) {
    throw std::invalid_argument("SampleDelay: delays must be in [0, 1) s");
  }
}

ImuSample SampleDelay::apply(const ImuSample& s) {
  history_.push_back(s);
  const auto keep_ns = static_cast<int64_t>(std::ceil(std::max(accel_delay_s_, gyro_delay_s_) * 1e9));
  // keep one sample at or before t - max delay
  while (history_.size() > 2 && history_[1].stamp_ns <= s.stamp_ns - keep_ns) {
    history_.pop_front();
  }
  ImuSample out = s;
  out.accel_mps2 = at_time(history_, s.stamp_ns - static_cast<int64_t>(std::llround(accel_delay_s_ * 1e9)),
                           [](const ImuSample& x) { return x.accel_mps2; });
  out.gyro_rps = at_time(history_, s.stamp_ns - static_cast<int64_t>(std::llround(gyro_delay_s_ * 1e9)),
                         [](const ImuSample& x) { return x.gyro_rps; });
  return out;
}

}  // namespace poise::sim
