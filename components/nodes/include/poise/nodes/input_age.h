// How old an input sample is when it arrives, and the rule that no estimator fuses one older than
// its input deadline (issue 37: after a link cut the network delivered samples 2.5-4.7 s old and the
// parallel KF fused them). Pure bookkeeping, like InputHealth: the caller passes the arrival time
// (the node reads the clock) and serialises calls.
//
// A sample's stamp is on its publisher's clock (`header.stamp_ns`: the IMU host's CLOCK_MONOTONIC),
// its arrival on this host's clock. Two methods:
//  - kRelative (default): sound whatever the two clocks are. Per publisher, offset = arrival - stamp
//    is the delivery delay plus an unknown constant (the clocks' difference). The smallest offset
//    seen so far is the freshest delivery; a sample's age is how much later than that it arrived:
//    age = offset - min_offset (a lower bound of the true age, short by the fastest delivery
//    delay, well under 1 ms on a LAN). The minimum is allowed to rise by kDriftAllowance s/s so
//    that clocks drifting apart never make fresh samples look old. A new publisher starts a new
//    reference; so does one whose samples stay stale for more than kReanchorAfterNs (1 s) of
//    arrivals with no fresh one between (its clock was reset, a replay looped, or the path's delay
//    grew for good: without synchronised clocks a lasting delay cannot be told from a clock
//    offset, so after 1 s it becomes the new normal; counted as T_age_reanchored).
//  - kHostClock: age = arrival - stamp, only sound when the stamps are on this host's clock (the
//    publisher runs on this host, or its clock is synchronised to this one, e.g. PTP); a stamp from
//    the future counts as age 0. Across hosts with unsynchronised CLOCK_MONOTONIC (boot times
//    differ) the ages are meaningless: every sample may be rejected, or none.
//  - kOff: ages are neither judged nor reported.
// A sample older than the deadline is stale: the caller does not fuse it and it is counted
// (`T_stale`); the ages of the fused samples are reported (`T_age` the last, `T_age_max` the
// oldest since start, s), so the age of every fused sample is bounded by the deadline and shown.
#pragma once

#include "poise/nodes/reports.h"

#include <cstdint>
#include <map>
#include <string>
#include <utility>

namespace poise::nodes {

enum class AgeMethod { kRelative, kHostClock, kOff };

/// "relative", "host_clock", "off" (the spelling of the `input_age` parameter).
const char* to_string(AgeMethod method);
/// The method named `name`; throws std::invalid_argument naming the allowed values.
AgeMethod parse_age_method(const std::string& name);

class InputAge {
 public:
  /// How fast the minimum offset may rise (s/s): 500 ppm, the most NTP slews a clock; crystals
  /// drift by under 100 ppm. After a 5 s silence the reference has moved by 2.5 ms.
  static constexpr double kDriftAllowance = 5e-4;
  /// Samples of one publisher stale for longer than this (arrival time, no fresh one between):
  /// the reference is wrong, a new one starts (`T_age_reanchored`). A stale burst after a link
  /// cut arrives within milliseconds and never reaches it.
  static constexpr int64_t kReanchorAfterNs = 1'000'000'000;

  /// `max_age_ns`: a sample older than this when it arrives is stale.
  InputAge(AgeMethod method, int64_t max_age_ns) : method_(method), max_age_ns_(max_age_ns) {}

  struct Verdict {
    int64_t age_ns = 0;  ///< 0 with kOff
    bool stale = false;
  };
  /// Judges one sample of `topic` from `writer` (an identity of its publisher) stamped `stamp_ns`
  /// by it and arrived at `arrival_ns` on this host; counts it when stale.
  Verdict judge(const std::string& topic, const std::string& writer, int64_t stamp_ns,
                int64_t arrival_ns);
  /// A sample judged fresh with `age_ns` was fused (its age enters the report).
  void fused(const std::string& topic, int64_t age_ns);
  /// Adds, per topic judged so far: counters T_stale, T_age_reanchored; metrics T_age, T_age_max
  /// (s). Nothing with kOff.
  void report(DiagnosticsReport& out) const;

  [[nodiscard]] uint64_t stale(const std::string& topic) const;
  [[nodiscard]] AgeMethod method() const { return method_; }
  [[nodiscard]] int64_t max_age_ns() const { return max_age_ns_; }

 private:
  struct Reference {
    int64_t offset_ns = 0;        ///< the smallest arrival - stamp, as of arrival_ns
    int64_t arrival_ns = 0;
    int64_t stale_since_ns = -1;  ///< arrival of the first of the current run of stale samples
    bool early_pending = false;   ///< one sample came more than the deadline "early" (stamp ahead)
    int64_t early_offset_ns = 0;  ///< its arrival - stamp
  };
  struct Topic {
    uint64_t stale = 0;
    uint64_t reanchored = 0;
    int64_t last_age_ns = 0;
    int64_t max_age_ns = 0;
  };
  int64_t relative_age(const std::string& topic, const std::string& writer, int64_t stamp_ns,
                       int64_t arrival_ns);

  AgeMethod method_;
  int64_t max_age_ns_;
  std::map<std::pair<std::string, std::string>, Reference> references_;  // (topic, writer)
  std::map<std::string, Topic> topics_;
};

}  // namespace poise::nodes
