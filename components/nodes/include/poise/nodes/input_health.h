// Loss and silence of a node's inputs (issue 22): per input topic, the samples lost on the way
// (header.seq gaps, poise::dds::SequenceGaps), publisher restarts, and how long the input has been
// silent against a deadline. Pure bookkeeping: the caller passes the time (the node base reads the
// clock) and serialises calls (the node's mutex). report() adds, per input topic T:
//   counters T_received, T_lost (sum of seq gaps: the exact number of samples that never
//            arrived between two that did), T_gaps, T_restarts (a new writer: counted, not a loss),
//            T_silences (times the input went silent for longer than the deadline)
//   metrics  T_silence (s since the last sample, or since start when none came yet),
//            T_silent (1 while the silence exceeds the deadline)
#pragma once

#include "poise/dds/sequence_gaps.h"
#include "poise/nodes/reports.h"

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace poise::nodes {

class InputHealth {
 public:
  /// `deadline_ns`: an input silent for longer is reported silent. `start_ns`: when listening began.
  InputHealth(int64_t deadline_ns, int64_t start_ns);

  /// Declares an input reported from the start (silence counts from start_ns). Inputs only seen
  /// through on_sample() (optional ones, e.g. vision) are reported from their first sample.
  void expect(const std::string& topic);
  /// One sample of `topic` from `source` (sensor_id) with header.seq `seq`, written by `writer`
  /// (dds::writer_key), arrived at `now_ns`. Returns the samples lost just before it.
  uint64_t on_sample(const std::string& topic, const std::string& source, uint32_t seq,
                     const std::string& writer, int64_t now_ns);
  /// Updates the silence state at `now_ns` (counts a new silence once per episode).
  void tick(int64_t now_ns);
  /// Adds the counters and metrics above (calls tick(now_ns) first).
  void report(int64_t now_ns, DiagnosticsReport& out);

  struct Silence {
    std::string topic;
    double seconds = 0.0;
  };
  /// The inputs silent beyond the deadline at `now_ns`, longest first.
  [[nodiscard]] std::vector<Silence> silent(int64_t now_ns) const;
  [[nodiscard]] dds::SequenceGaps::Totals totals(const std::string& topic) const;

 private:
  struct Input {
    dds::SequenceGaps gaps;
    int64_t last_ns = 0;  ///< arrival of the last sample (start_ns before the first)
    bool silent = false;
    uint64_t silences = 0;
  };
  Input& input(const std::string& topic);

  int64_t deadline_ns_;
  int64_t start_ns_;
  std::map<std::string, Input> inputs_;
};

/// "no input on imu for 5.2 s" for every silent input, "; "-joined; empty when none is silent.
std::string describe_silence(const std::vector<InputHealth::Silence>& silent);

}  // namespace poise::nodes
