// `poise record`: subscribes to topics (discovered on the domain) with the raw type and writes
// their serialized payloads to MCAP without deserializing.
//  - channel: topic, message encoding "cdr", schema "omgidl" (flattened IDL of the DDS type),
//    metadata = the topic's QoS as discovered (reliability, durability) + the poise QoS profile;
//  - log_time = reception (log clock, default CLOCK_REALTIME ns); publish_time = Header.stamp_ns
//    read from the payload (bytes 4-11), or the writer's source timestamp when it has none;
//  - sequence = the DDS writer's sample sequence number (low 32 bits): gaps reveal losses; a
//    writer's first sample received tells how many it wrote before the recorder matched it (DDS
//    sequence numbers start at 1 per writer), counted as `before_match`.
// Every payload is checked against its IDL type before it is queued (schema::payload_problem):
// a malformed one from any participant is counted per topic, reported, and not written; the
// recording goes on.
#pragma once

#include "poise/record/mcap.h"

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

namespace poise::record {

struct RecorderOptions {
  std::string output;               ///< FILE.mcap (with a split size: FILE_000.mcap, ...)
  std::vector<std::string> topics;  ///< topics to record (ignored with `all`)
  bool all = false;                 ///< record every topic of a known poise type
  int domain = 0;
  std::string participant_profile;  ///< "" = $POISE_DDS_PROFILE / poise_default
  double duration_s = 0.0;          ///< stop after this long (0 = until stopped)
  uint64_t split_size_bytes = 0;    ///< start a new file past this size (0 = one file)
  WriterOptions writer;             ///< chunking, compression
  size_t max_queue_messages = 1'000'000;  ///< beyond this, incoming samples are dropped (counted)
  std::function<bool()> should_stop;      ///< polled every 100 ms
  std::function<int64_t()> log_clock;     ///< log time (ns); default CLOCK_REALTIME
  std::ostream* log = nullptr;            ///< progress and warnings (stderr when null)
};

struct TopicStats {
  std::string type;
  uint64_t received = 0;  ///< samples handed to the recorder by DDS
  uint64_t written = 0;   ///< messages in the file(s): in complete, durable chunks
  uint64_t lost = 0;      ///< valid samples received but not in the file (write error)
  uint64_t dropped = 0;   ///< dropped because the write queue was full
  uint64_t gaps = 0;      ///< samples missing according to writer sequence numbers
  /// Samples each writer wrote before the recorder matched it (its first sample's DDS sequence
  /// number - 1, per writer): never offered to the recorder, not in the file, not in `gaps`.
  uint64_t before_match = 0;
  uint64_t malformed = 0;  ///< rejected: not a valid payload of `type` (never written)
  std::string first_problem;  ///< why the first malformed payload was rejected
};

struct RecorderStats {
  std::map<std::string, TopicStats> topics;
  uint64_t received = 0;
  uint64_t written = 0;  ///< in the file(s); received = written + malformed + dropped + lost
  uint64_t lost = 0;     ///< never reached a durable chunk (write error: disk full, ...)
  uint64_t dropped_queue_full = 0;
  uint64_t sequence_gaps = 0;
  uint64_t before_match = 0;  ///< all topics (see TopicStats::before_match)
  uint64_t malformed = 0;  ///< all topics (see TopicStats::malformed)
  std::vector<std::string> files;
  double elapsed_s = 0.0;
  std::string error;  ///< non-empty when recording stopped on a write error
};

class Recorder {
 public:
  explicit Recorder(RecorderOptions options);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  /// Records until should_stop(), the duration, request_stop() or a write error. Files are
  /// always finalised. Throws poise::dds::DdsError / WriteError on setup failures.
  RecorderStats run();
  /// Asks run() to finish (thread-safe).
  void request_stop() { stop_.store(true); }
  /// Number of topics subscribed so far (thread-safe).
  [[nodiscard]] int subscribed() const { return subscribed_.load(); }
  /// Messages handed to the MCAP writer so far (progress; durable counts are in RecorderStats).
  [[nodiscard]] uint64_t written() const { return written_.load(); }
  /// Remote writers currently matched by the recorder's readers, all topics (thread-safe).
  [[nodiscard]] int matched_writers() const { return matched_.load(); }

 private:
  struct Impl;
  RecorderOptions options_;
  std::unique_ptr<Impl> impl_;
  std::atomic<bool> stop_{false};
  std::atomic<int> subscribed_{0};
  std::atomic<uint64_t> written_{0};
  std::atomic<int> matched_{0};
};

/// FILE.mcap -> FILE_<index>.mcap (3 digits) for split recordings.
std::string split_file_name(const std::string& output, int index);

}  // namespace poise::record
