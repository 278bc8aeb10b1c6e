// The serial IMU driver core: bytes + arrival time in, calibrated host-stamped samples out.
// Pure (no I/O, no clock reads, no threads): the port reader feeds it, tests and the fuzzer too.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <string>
#include <string_view>

#include "poise/core/types.h"
#include "poise/imu/calibration.h"
#include "poise/imu/framer.h"
#include "poise/imu/protocol.h"
#include "poise/imu/sensor_info.h"
#include "poise/imu/timing.h"

#include <optional>

namespace poise::imu {

struct DriverParams {
  Limits limits;
  RawScale raw;
  SequenceParams sequence;
  ClockSyncParams clock;
  /// Serial throughput in bytes/s (baud / 10 for 8N1) used to move each line's arrival back by its
  /// transmission time before clock estimation; 0 disables (pseudo-terminals, USB-native boards).
  double link_bytes_per_s = 0.0;
  /// Time from sampling to the first byte on the wire (firmware formatting), s; >= 0.
  double sensor_latency_s = 0.0;
};

/// Everything about one accepted sample that is not in ImuSample.
struct SampleInfo {
  RawSample raw;            ///< parsed, uncalibrated, sensor axes (for calibration tools)
  int64_t sensor_ns = 0;    ///< unwrapped sensor clock
  int64_t arrival_ns = 0;   ///< host time the line's last byte was read
};

/// Counters since construction (never reset by reconnects).
struct DriverStats {
  uint64_t bytes = 0;        ///< bytes fed
  uint64_t lines = 0;        ///< candidate '$' lines framed
  uint64_t samples = 0;      ///< samples published
  uint64_t info_lines = 0;   ///< '#' firmware messages
  uint64_t samples_without_mag = 0;  ///< published with has_mag = false (empty or saturated)
  RejectCounts rejects{};    ///< per RejectReason
  uint64_t seq_gap_drops = 0;  ///< lines lost according to sequence gaps
  uint64_t sensor_restarts = 0;  ///< seq jumps treated as a sensor restart (resync)
  uint64_t disconnects = 0;  ///< reset() calls (port lost)
  uint64_t clock_resets = 0;
  uint64_t clock_reanchors = 0;  ///< sensor clock jumps accepted after reanchor_samples agreed
  int64_t clock_offset_ns = 0;  ///< stamp - sensor time of the last sample
  double clock_drift_ppm = 0.0;
  bool clock_valid = false;
  /// Sensor time over host arrival time, measured over kClockRatioWindowS of arrivals (0: not yet).
  /// 1.0 within the clock's drift; far from it (t_us in the wrong unit) the stamps cannot follow the
  /// arrivals: clock_ratio_problem() says so.
  double clock_ratio = 0.0;
  std::string last_info;     ///< last '#' message from the firmware
  uint64_t sensor_info_lines = 0;  ///< $INF lines accepted (repeats of the info in effect included)
  std::string last_info_problem;   ///< why the last refused $INF line was refused
  [[nodiscard]] uint64_t rejected_total() const;
};

/// Host time over which DriverStats::clock_ratio is measured, s.
inline constexpr double kClockRatioWindowS = 5.0;
/// A sensor clock this far from the host's (ratio below 1/x or above x) is not drift: a unit error.
inline constexpr double kClockRatioLimit = 1.5;

/// "" while the sensor clock keeps the host's pace; else what is wrong, e.g. "the sensor clock
/// advances at 0.10 x host time (t_us +0.50 s in 5.00 s of arrivals): is the firmware's t_us in
/// microseconds? stamps cannot follow the arrivals (samples are dropped as stale)".
std::string clock_ratio_problem(const DriverStats& stats);

using SampleSink = std::function<void(const ImuSample&, const SampleInfo&)>;
/// Called when the sensor's delay becomes known or changes (a new $INF after a restart).
using DelaySink = std::function<void(const SensorDelay&)>;
/// Called with the message of each refused $INF line (unknown setting, conflict, ...).
using InfoProblemSink = std::function<void(const std::string&)>;

class ImuDriver : private FrameSink {
 public:
  ImuDriver(const DriverParams& params, const Calibration& calibration, SampleSink sink);
  /// Feeds bytes read at host time `arrival_ns` (CLOCK_MONOTONIC ns, read by the caller).
  void feed(const char* data, std::size_t size, int64_t arrival_ns);
  void feed(std::string_view data, int64_t arrival_ns) { feed(data.data(), data.size(), arrival_ns); }
  /// The byte stream broke (unplug, reconnect): drops a partial line, restarts sequence and clock
  /// tracking (an Arduino resets when its port is opened).
  void reset();
  [[nodiscard]] const DriverStats& stats() const { return stats_; }
  void set_link_bytes_per_s(double v) { params_.link_bytes_per_s = v; }
  [[nodiscard]] const DriverParams& params() const { return params_; }
  /// The sensor's delay from its $INF line; empty until one was accepted (old firmware: never).
  [[nodiscard]] const std::optional<SensorDelay>& sensor_delay() const { return delay_; }
  void set_delay_sink(DelaySink sink) { delay_sink_ = std::move(sink); }
  void set_info_problem_sink(InfoProblemSink sink) { info_problem_sink_ = std::move(sink); }

 private:
  void on_info_line(const SensorInfoLine& line, std::size_t bytes);
  void on_line(std::string_view line) override;
  void on_info(std::string_view text) override;
  void on_reject(RejectReason reason, std::size_t bytes) override;
  /// Measures DriverStats::clock_ratio over windows of kClockRatioWindowS of arrivals.
  void watch_clock_ratio(int64_t sensor_ns, int64_t arrival_ns);

  DriverParams params_;
  Calibration calibration_;
  SampleSink sink_;
  LineParser parser_;
  LineFramer framer_;
  SequenceTracker sequence_;
  TimeUnwrapper time_;
  ClockSync clock_;
  ClockJumpAnchor jump_;
  int64_t arrival_ns_ = 0;
  int64_t last_sensor_ns_ = 0;
  // clock ratio window: its first sample's sensor and arrival times (window_ns_ < 0: none)
  int64_t window_sensor_ns_ = 0;
  int64_t window_arrival_ns_ = -1;
  DriverStats stats_;
  std::optional<SensorDelay> delay_;
  /// A different $INF may replace the one in effect: at the start, after a reset (reconnect) or a
  /// sensor restart (the board may have been reflashed); otherwise a different one is a conflict.
  bool delay_replaceable_ = true;
  DelaySink delay_sink_;
  InfoProblemSink info_problem_sink_;
};

/// Sample rate and latency (arrival - stamp) over a sliding window of host time (pure).
class RateLatencyMeter {
 public:
  explicit RateLatencyMeter(double window_s = 2.0) : window_ns_(static_cast<int64_t>(window_s * 1e9)) {}
  void add(int64_t stamp_ns, int64_t arrival_ns);
  struct Summary {
    double rate_hz = 0;
    double latency_p50_ms = 0;
    double latency_p99_ms = 0;
    double latency_max_ms = 0;
    std::size_t count = 0;
  };
  /// Summary of the samples that arrived within the window before `now_ns`.
  [[nodiscard]] Summary summarize(int64_t now_ns);

 private:
  int64_t window_ns_;
  std::deque<std::pair<int64_t, int64_t>> items_;  // (arrival, latency)
};

}  // namespace poise::imu
