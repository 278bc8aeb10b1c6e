#include "poise/imu/driver.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

namespace poise::imu {

uint64_t DriverStats::rejected_total() const {
  uint64_t n = 0;
  for (const uint64_t c : rejects) n += c;
  return n;
}

ImuDriver::ImuDriver(const DriverParams& params, const Calibration& calibration, SampleSink sink)
    : params_(params),
      calibration_(calibration),
      sink_(std::move(sink)),
      parser_(params.limits, params.raw),
      sequence_(params.sequence),
      clock_(params.clock),
      jump_(params.clock.reanchor_samples, params.clock.reset_threshold_s, params.sequence.max_forward_gap) {}

void ImuDriver::feed(const char* data, std::size_t size, int64_t arrival_ns) {
  stats_.bytes += size;
  arrival_ns_ = arrival_ns;
  framer_.feed(data, size, *this);
}

void ImuDriver::reset() {
  framer_.reset(*this);
  sequence_.reset();
  time_.reset();
  clock_.reset();
  jump_.clear();
  window_arrival_ns_ = -1;
  delay_replaceable_ = true;
  ++stats_.disconnects;
}

void ImuDriver::on_info_line(const SensorInfoLine& line, std::size_t bytes) {
  InfoResolution r = resolve_sensor_info(line);
  if (r.delay && delay_ && *r.delay != *delay_ && !delay_replaceable_) {
    r.reason = RejectReason::kInfoConflict;
    r.message = "$INF: " + r.delay->describe() + " contradicts the info in effect since the sensor started, " +
                delay_->describe() + ": kept (a new setting is taken after a sensor restart)";
    r.delay.reset();
  }
  if (!r.delay) {
    on_reject(r.reason, bytes);
    stats_.last_info_problem = r.message;
    if (info_problem_sink_) info_problem_sink_(r.message);
    return;
  }
  ++stats_.sensor_info_lines;
  delay_replaceable_ = false;
  if (delay_ && *delay_ == *r.delay) return;
  delay_ = *r.delay;
  if (delay_sink_) delay_sink_(*delay_);
}

void ImuDriver::on_info(std::string_view text) {
  ++stats_.info_lines;
  stats_.last_info.assign(text.data(), text.size());
}

void ImuDriver::on_reject(RejectReason reason, std::size_t /*bytes*/) {
  ++stats_.rejects[static_cast<std::size_t>(reason)];
}

void ImuDriver::on_line(std::string_view line) {
  ++stats_.lines;
  const ParseResult r = parser_.parse(line);
  if (!r.ok) {
    on_reject(r.reason, line.size());
    return;
  }
  if (r.is_info) {
    on_info_line(r.info, line.size());
    return;
  }
  const RawSample& raw = r.sample;
  uint32_t gap = 0;
  SequenceTracker::Verdict verdict = sequence_.check(raw.seq, &gap);
  switch (verdict) {
    case SequenceTracker::Verdict::kDuplicate:
      on_reject(RejectReason::kDuplicateSeq, line.size());
      return;
    case SequenceTracker::Verdict::kOutOfOrder:
      on_reject(RejectReason::kOutOfOrderSeq, line.size());
      return;
    case SequenceTracker::Verdict::kRestart:
      // The sensor restarted (or its counter jumped): resynchronise on this sample.
      ++stats_.sensor_restarts;
      window_arrival_ns_ = -1;
      delay_replaceable_ = true;
      sequence_.reset();
      time_.reset();
      clock_.reset();
      verdict = SequenceTracker::Verdict::kFirst;
      gap = 0;
      break;
    case SequenceTracker::Verdict::kFirst:
    case SequenceTracker::Verdict::kNext:
      break;
  }
  int64_t sensor_ns = time_.peek_ns(raw.t_us);
  if (verdict == SequenceTracker::Verdict::kNext && time_.has_last() &&
      sensor_ns <= last_sensor_ns_) {
    // t_us went back (or forward by 2^31 us or more, which unwraps as back) while seq counted on.
    if (!jump_.refused(raw.seq, raw.t_us)) {
      on_reject(RejectReason::kTimeNotMonotonic, line.size());
      return;
    }
    // reanchor_samples consecutive lines agree on the new clock: restart the time base here
    // (ClockSync keeps published stamps increasing across its reset).
    ++stats_.clock_reanchors;
    window_arrival_ns_ = -1;
    time_.reset();
    clock_.reset();
    sensor_ns = time_.peek_ns(raw.t_us);
  } else {
    jump_.clear();
  }
  sequence_.commit(raw.seq);
  time_.commit(raw.t_us);
  last_sensor_ns_ = sensor_ns;
  stats_.seq_gap_drops += gap;

  // Arrival of the line's first byte at best: remove its transmission time ("\r\n" included).
  double correction_ns = params_.sensor_latency_s * 1e9;
  if (params_.link_bytes_per_s > 0) {
    correction_ns += static_cast<double>(line.size() + 1) / params_.link_bytes_per_s * 1e9;
  }
  const int64_t arrival_first_byte = arrival_ns_ - static_cast<int64_t>(std::llround(correction_ns));
  ImuSample s;
  calibration_.apply(raw, &s);
  s.stamp_ns = clock_.update(sensor_ns, arrival_first_byte);
  stats_.clock_offset_ns = clock_.offset_ns();
  stats_.clock_drift_ppm = clock_.drift_ppm();
  stats_.clock_valid = clock_.valid();
  stats_.clock_resets = clock_.resets();
  watch_clock_ratio(sensor_ns, arrival_first_byte);
  ++stats_.samples;
  if (!raw.has_mag) ++stats_.samples_without_mag;
  if (sink_) {
    SampleInfo info;
    info.raw = raw;
    info.sensor_ns = sensor_ns;
    info.arrival_ns = arrival_ns_;
    sink_(s, info);
  }
}

void ImuDriver::watch_clock_ratio(int64_t sensor_ns, int64_t arrival_ns) {
  const auto window_ns = static_cast<int64_t>(kClockRatioWindowS * 1e9);
  if (window_arrival_ns_ < 0 || sensor_ns < window_sensor_ns_ || arrival_ns < window_arrival_ns_) {
    window_sensor_ns_ = sensor_ns;
    window_arrival_ns_ = arrival_ns;
    return;
  }
  if (arrival_ns - window_arrival_ns_ >= window_ns) {
    stats_.clock_ratio = static_cast<double>(sensor_ns - window_sensor_ns_) /
                         static_cast<double>(arrival_ns - window_arrival_ns_);
    window_sensor_ns_ = sensor_ns;
    window_arrival_ns_ = arrival_ns;
  }
}

std::string clock_ratio_problem(const DriverStats& stats) {
  const double r = stats.clock_ratio;
  if (r == 0.0 || (r >= 1.0 / kClockRatioLimit && r <= kClockRatioLimit)) {
    return "";
  }
  char text[320];
  std::snprintf(text, sizeof text,
                "the sensor clock advances at %.2f x host time (t_us +%.2f s in %.2f s of arrivals): is the "
                "firmware's t_us in microseconds? stamps cannot follow the arrivals (samples are dropped as stale)",
                r, r * kClockRatioWindowS, kClockRatioWindowS);
  return text;
}

void RateLatencyMeter::add(int64_t stamp_ns, int64_t arrival_ns) {
  items_.emplace_back(arrival_ns, arrival_ns - stamp_ns);
}

RateLatencyMeter::Summary RateLatencyMeter::summarize(int64_t now_ns) {
  while (!items_.empty() && items_.front().first < now_ns - window_ns_) items_.pop_front();
  Summary s;
  s.count = items_.size();
  if (items_.empty()) return s;
  const int64_t span_ns = items_.back().first - items_.front().first;
  if (items_.size() >= 2 && span_ns > 0) {
    s.rate_hz = static_cast<double>(items_.size() - 1) / (static_cast<double>(span_ns) * 1e-9);
  }
  std::vector<int64_t> lat;
  lat.reserve(items_.size());
  for (const auto& it : items_) lat.push_back(it.second);
  std::sort(lat.begin(), lat.end());
  const auto pct = [&lat](double q) {
    const auto i = static_cast<std::size_t>(q * static_cast<double>(lat.size() - 1) + 0.5);
    return static_cast<double>(lat[std::min(i, lat.size() - 1)]) * 1e-6;
  };
  s.latency_p50_ms = pct(0.5);
  s.latency_p99_ms = pct(0.99);
  s.latency_max_ms = static_cast<double>(lat.back()) * 1e-6;
  return s;
}

}  // namespace poise::imu
