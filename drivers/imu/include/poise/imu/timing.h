// Sequence tracking and sensor-clock handling (pure: time is an input, no clock reads).
//
// Clock model: a sample sampled at sensor time s (unwrapped, ns) reaches the host at
//   a = s + o + r * (s - s0) + delay,   delay >= 0,
// with o the clock offset, r the relative drift (host rate / sensor rate - 1) and `delay` the
// transport latency (USB polling, scheduling). The minimum delay is reached often, so the lower
// envelope of d = a - s over the recent past is the line o + r (s - s0). ClockSync keeps the minima
// of d over blocks of sensor time, builds their lower convex hull and takes the hull edge under the
// block points' mean time: the supporting line that minimises the mean gap to the points. The
// stamp is s + o + r (s - s0) on the host clock (sampling time, not arrival time).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>

namespace poise::imu {

/// Sequence-number checks with uint32 wrap-around.
struct SequenceParams {
  uint32_t reorder_window = 64;     ///< a seq this far behind the last one is out-of-order; further
                                    ///< behind means the sensor restarted (resync)
  uint32_t max_forward_gap = 100000;  ///< a larger forward jump is a restart, not lost lines
};

class SequenceTracker {
 public:
  enum class Verdict { kFirst, kNext, kDuplicate, kOutOfOrder, kRestart };
  explicit SequenceTracker(const SequenceParams& p = {}) : params_(p) {}
  /// Classifies `seq` against the last committed one; `gap` = lines missing before it (kNext).
  [[nodiscard]] Verdict check(uint32_t seq, uint32_t* gap) const;
  void commit(uint32_t seq) {
    last_ = seq;
    has_last_ = true;
  }
  void reset() { has_last_ = false; }
  [[nodiscard]] bool has_last() const { return has_last_; }

 private:
  SequenceParams params_;
  uint32_t last_ = 0;
  bool has_last_ = false;
};

/// Unwraps the uint32 microsecond counter into int64 nanoseconds.
class TimeUnwrapper {
 public:
  /// The unwrapped time of `t_us` relative to the last committed one (signed 31-bit step).
  [[nodiscard]] int64_t peek_ns(uint32_t t_us) const;
  void commit(uint32_t t_us);
  void reset() { has_last_ = false; }
  [[nodiscard]] bool has_last() const { return has_last_; }

 private:
  uint32_t last_ = 0;
  int64_t last_us_ = 0;
  bool has_last_ = false;
};

struct ClockSyncParams {
  double block_s = 0.5;        ///< envelope block length (sensor time), s. Longer: smoother, slower
  int window_blocks = 60;      ///< blocks kept (window = block_s * window_blocks), >= 2
  double max_drift_ppm = 20000.0;  ///< |drift| clamp (ceramic resonators reach 5000 ppm)
  double reset_threshold_s = 1.0;  ///< a block whose minimum departs the envelope by more than
                                   ///< this (or any point below it by more) restarts the estimate
  /// The sensor clock jumped (back, or forward by 2^31 us or more) while seq kept counting: the
  /// time base restarts at the N-th consecutive such sample when each follows the previous one
  /// by 0 < dt <= reset_threshold_s per seq step (ClockJumpAnchor); the N-1 before it are
  /// rejected as time_not_monotonic. >= 2: one wild t_us costs one line, never the time base.
  int reanchor_samples = 3;
};

/// Decides when a sensor clock that jumped is the new truth (pure). Every line refused because
/// its t_us did not advance while seq did is offered to refused(); the run of refused lines must
/// be consecutive (seq forward by at most `max_seq_step`) and agree with each other (t_us forward
/// by more than 0 and at most `max_step_s` per seq step); at the `samples`-th the time base
/// restarts. An accepted line clears the run.
class ClockJumpAnchor {
 public:
  ClockJumpAnchor(int samples, double max_step_s, uint32_t max_seq_step)
      : samples_(samples), max_step_us_(max_step_s * 1e6), max_seq_step_(max_seq_step) {}
  /// True: restart the time base at this line (and clear the run).
  bool refused(uint32_t seq, uint32_t t_us);
  void clear() { run_ = 0; }

 private:
  int samples_;
  double max_step_us_;
  uint32_t max_seq_step_;
  int run_ = 0;
  uint32_t last_seq_ = 0;
  uint32_t last_t_us_ = 0;
};

class ClockSync {
 public:
  explicit ClockSync(const ClockSyncParams& p = {});
  /// Feeds one sample (sensor time, host arrival time; both ns) and returns its host-clock stamp.
  /// Stamps are strictly increasing and causal (<= arrival), except that samples clamped to the
  /// same arrival (several lines in one read before the offset is known) are spread by 1 ns.
  int64_t update(int64_t sensor_ns, int64_t arrival_ns);
  void reset();
  /// Offset o(s) = stamp - sensor time at the last sample, ns.
  [[nodiscard]] int64_t offset_ns() const { return last_offset_ns_; }
  [[nodiscard]] double drift_ppm() const { return slope_ * 1e6; }
  [[nodiscard]] bool valid() const { return initialized_; }
  [[nodiscard]] uint64_t resets() const { return resets_; }

 private:
  struct Point {
    double t;  // sensor time since t0_, ns
    double d;  // arrival - sensor, ns, relative to d0_
  };
  void refit();
  [[nodiscard]] double envelope(double t) const { return intercept_ + slope_ * t; }

  ClockSyncParams params_;
  bool initialized_ = false;
  int64_t t0_ = 0;
  int64_t d0_ = 0;
  std::deque<Point> blocks_;
  Point current_{0, 0};
  double block_start_ = 0;
  bool has_current_ = false;
  double slope_ = 0;
  double intercept_ = 0;
  int64_t last_stamp_ = 0;
  bool has_stamp_ = false;  // kept across reset(): stamps stay increasing over reconnects
  int64_t last_offset_ns_ = 0;
  uint64_t resets_ = 0;
};

}  // namespace poise::imu
