#include "poise/ros2_bridge/input.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace poise::ros2 {
namespace {
constexpr std::size_t kMaxBuffered = 64;  // side samples kept for pairing (> 0.1 s at 500 Hz)

/// REP 145: element 0 of a covariance = -1 says the driver does not provide that part.
bool provided(const std::array<double, 9>& covariance) { return covariance[0] != -1.0; }
}  // namespace

ImuAssembler::ImuAssembler(InputConfig config)
    : config_(std::move(config)),
      tolerance_ns_(static_cast<int64_t>(std::llround(config_.pair_tolerance_s * 1e9))),
      stale_ns_(static_cast<int64_t>(std::llround(config_.stale_s * 1e9))),
      jump_ns_(static_cast<int64_t>(std::llround(config_.max_jump_s * 1e9))) {
  mag_.enabled = config_.mag;
  pressure_.enabled = config_.pressure;
}

uint64_t ImuAssembler::rejected_total() const {
  uint64_t n = 0;
  for (const auto& [reason, count] : rejected_) {
    n += count;
  }
  return n;
}

std::vector<ImuSample> ImuAssembler::on_imu(const ros_sensor::Imu_& m) {
  const std::optional<int64_t> stamp = from_ros_time(m.header().stamp(), config_.offset_ns);
  if (!stamp) {
    reject("imu_bad_stamp");
    return {};
  }
  ImuSample s;
  s.stamp_ns = *stamp;
  s.gyro_rps = {m.angular_velocity().x(), m.angular_velocity().y(), m.angular_velocity().z()};
  s.accel_mps2 = {m.linear_acceleration().x(), m.linear_acceleration().y(), m.linear_acceleration().z()};
  s.has_gyro = provided(m.angular_velocity_covariance());
  s.has_accel = provided(m.linear_acceleration_covariance());
  s.has_mag = false;
  s.has_pressure = false;
  RejectCounters counters;
  if (last_stamp_ns_ >= 0 && far(s.stamp_ns, last_stamp_ns_)) {
    const SampleCheck values = check_imu_sample(s, -1, config_.limits, counters);  // its values alone
    if (!values.accept) {
      reject(std::string("imu_") + to_string(values.reject));
      return {};
    }
    return on_jump(s);
  }
  const SampleCheck check = check_imu_sample(s, last_stamp_ns_, config_.limits, counters);
  if (!check.accept && check.reject != RejectReason::kTimeGap) {
    reject(std::string("imu_") + to_string(check.reject));
    return {};
  }
  // Agrees with the time base: a run of jumped stamps was wild, not a new clock.
  for (std::size_t i = 0; i < jumped_.size(); ++i) {
    reject("imu_stamp_jump");
  }
  jumped_.clear();
  // A time gap (up to max_jump_s) is forwarded: the estimators re-anchor on it themselves.
  const bool first = last_stamp_ns_ < 0;
  last_stamp_ns_ = s.stamp_ns;
  if (first) {
    rebase_sides(s.stamp_ns);
  }
  pending_.push_back(s);
  return drain();
}

bool ImuAssembler::far(int64_t stamp_ns, int64_t base_ns) const {
  // in double: both are in [0, 2^62], their difference fits, but keep it plain
  return std::abs(static_cast<double>(stamp_ns) - static_cast<double>(base_ns)) > static_cast<double>(jump_ns_);
}

std::vector<ImuSample> ImuAssembler::on_jump(const ImuSample& s) {
  const bool agrees = !jumped_.empty() && s.stamp_ns > jumped_.back().stamp_ns &&
                      !far(s.stamp_ns, jumped_.back().stamp_ns);
  if (!agrees) {
    for (std::size_t i = 0; i < jumped_.size(); ++i) {
      reject("imu_stamp_jump");
    }
    jumped_.clear();
  }
  jumped_.push_back(s);
  if (static_cast<int>(jumped_.size()) < std::max(config_.reanchor_samples, 2)) {
    return {};
  }
  // They agree: the clock really moved. The held samples go out on the new time base (those
  // pending on the old one first, paired with its side samples), then the side samples of the
  // old base are dropped.
  for (const ImuSample& held : jumped_) {
    pending_.push_back(held);
  }
  last_stamp_ns_ = jumped_.back().stamp_ns;
  jumped_.clear();
  std::vector<ImuSample> out = drain();
  rebase_sides(last_stamp_ns_);
  return out;
}

void ImuAssembler::rebase_sides(int64_t base_ns) {
  rebase_side(mag_, base_ns, "mag_stamp_jump");
  rebase_side(pressure_, base_ns, "pressure_stamp_jump");
}

void ImuAssembler::rebase_side(Stream& stream, int64_t base_ns, const char* reason) {
  const auto wild = std::remove_if(stream.buffer.begin(), stream.buffer.end(),
                                   [&](const Side& side) { return far(side.stamp_ns, base_ns); });
  for (auto it = wild; it != stream.buffer.end(); ++it) {
    reject(reason);
  }
  stream.buffer.erase(wild, stream.buffer.end());
  stream.newest_ns = -1;
  for (const Side& side : stream.buffer) {
    stream.newest_ns = std::max(stream.newest_ns, side.stamp_ns);
  }
}

std::vector<ImuSample> ImuAssembler::on_mag(const ros_sensor::MagneticField_& m) {
  if (!mag_.enabled) {
    return {};
  }
  const std::optional<int64_t> stamp = from_ros_time(m.header().stamp(), config_.offset_ns);
  if (!stamp || *stamp > kMaxStampNs) {
    reject("mag_bad_stamp");
    return {};
  }
  if (last_stamp_ns_ >= 0 && far(*stamp, last_stamp_ns_)) {
    reject("mag_stamp_jump");
    return {};
  }
  constexpr double kMicroteslaPerTesla = 1e6;
  const Eigen::Vector3d ut = Eigen::Vector3d(m.magnetic_field().x(), m.magnetic_field().y(),
                                             m.magnetic_field().z()) * kMicroteslaPerTesla;
  if (!ut.allFinite()) {
    reject("mag_non_finite");  // ROS: NaN in an axis the sensor does not measure
    return {};
  }
  if (!(ut.norm() <= config_.limits.max_mag_ut)) {
    reject("mag_out_of_range");
    return {};
  }
  if (!(ut.norm() >= config_.limits.min_mag_norm_ut)) {
    reject("mag_zero");
    return {};
  }
  add_side(mag_, {*stamp, ut});
  return drain();
}

std::vector<ImuSample> ImuAssembler::on_pressure(const ros_sensor::FluidPressure_& m) {
  if (!pressure_.enabled) {
    return {};
  }
  const std::optional<int64_t> stamp = from_ros_time(m.header().stamp(), config_.offset_ns);
  if (!stamp || *stamp > kMaxStampNs) {
    reject("pressure_bad_stamp");
    return {};
  }
  if (last_stamp_ns_ >= 0 && far(*stamp, last_stamp_ns_)) {
    reject("pressure_stamp_jump");
    return {};
  }
  const double pa = m.fluid_pressure();
  if (!std::isfinite(pa)) {
    reject("pressure_non_finite");
    return {};
  }
  if (!(pa >= config_.min_pressure_pa && pa <= config_.max_pressure_pa)) {
    reject("pressure_out_of_range");
    return {};
  }
  add_side(pressure_, {*stamp, Eigen::Vector3d(pa, 0.0, 0.0)});
  return drain();
}

void ImuAssembler::add_side(Stream& stream, Side side) {
  const auto at = std::upper_bound(stream.buffer.begin(), stream.buffer.end(), side.stamp_ns,
                                   [](int64_t t, const Side& s) { return t < s.stamp_ns; });
  stream.buffer.insert(at, side);
  stream.newest_ns = std::max(stream.newest_ns, side.stamp_ns);
  if (stream.buffer.size() > kMaxBuffered) {
    stream.buffer.pop_front();
  }
}

bool ImuAssembler::waits_for(const Stream& stream, int64_t stamp_ns) const {
  // Not yet at the stamp, but alive (never seen or stale streams are not waited for).
  return stream.enabled && stream.newest_ns >= 0 && stream.newest_ns < stamp_ns &&
         stream.newest_ns >= stamp_ns - stale_ns_;
}

bool ImuAssembler::take_nearest(Stream& stream, int64_t stamp_ns, Side& out) const {
  // Side samples too old for this IMU stamp are too old for every later one too.
  while (!stream.buffer.empty() && stream.buffer.front().stamp_ns < stamp_ns - tolerance_ns_) {
    stream.buffer.pop_front();
  }
  auto best = stream.buffer.end();
  int64_t best_diff = 0;
  for (auto it = stream.buffer.begin(); it != stream.buffer.end(); ++it) {
    const int64_t diff = it->stamp_ns > stamp_ns ? it->stamp_ns - stamp_ns : stamp_ns - it->stamp_ns;
    if (diff <= tolerance_ns_ && (best == stream.buffer.end() || diff < best_diff)) {
      best = it;
      best_diff = diff;
    }
  }
  if (best == stream.buffer.end()) {
    return false;
  }
  out = *best;
  stream.buffer.erase(best);
  return true;
}

std::vector<ImuSample> ImuAssembler::drain() {
  std::vector<ImuSample> out;
  while (!pending_.empty()) {
    ImuSample& s = pending_.front();
    const bool newest = pending_.size() == 1;  // an older one never waits behind a newer one
    if (newest && (waits_for(mag_, s.stamp_ns) || waits_for(pressure_, s.stamp_ns))) {
      break;
    }
    Side side{};
    if (mag_.enabled && take_nearest(mag_, s.stamp_ns, side)) {
      s.mag_ut = side.value;
      s.has_mag = true;
      ++paired_mag_;
    }
    if (pressure_.enabled && take_nearest(pressure_, s.stamp_ns, side)) {
      s.pressure_pa = side.value.x();
      s.has_pressure = true;
      ++paired_pressure_;
    }
    s.seq = seq_++;
    ++emitted_;
    out.push_back(s);
    pending_.pop_front();
  }
  return out;
}

}  // namespace poise::ros2
