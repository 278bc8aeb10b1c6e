// A Recorder running on its own thread, for the DDS recorder tests (test_record_dds,
// test_record_live, test_process_host): the one copy of start / stop-and-join / the log shown
// when discovery fails.
#pragma once

#include "poise/record/recorder.h"

#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <thread>
#include <utility>

namespace poise::record::testing {

/// Recorder options for a test: its output, its domain (a DomainLease's id) and profile.
inline RecorderOptions recorder_options(std::string output, int domain, std::string profile) {
  RecorderOptions o;
  o.output = std::move(output);
  o.domain = domain;
  o.participant_profile = std::move(profile);
  return o;
}

/// Runs `options` (its log replaced by this object's) on a thread from construction; stop() (or
/// the destructor) asks it to stop and joins.
class RecorderThread {
 public:
  explicit RecorderThread(RecorderOptions options) : recorder_(with_log(std::move(options))) {
    thread_ = std::thread([this] { stats_ = recorder_.run(); });
  }
  ~RecorderThread() { stop(); }
  RecorderThread(const RecorderThread&) = delete;
  RecorderThread& operator=(const RecorderThread&) = delete;

  Recorder* operator->() { return &recorder_; }
  /// Stops the recorder (once) and returns its statistics.
  const RecorderStats& stop() {
    if (thread_.joinable()) {
      recorder_.request_stop();
      thread_.join();
    }
    return stats_;
  }
  /// The recorder's log; read it after stop() (the recorder writes it from its thread).
  [[nodiscard]] std::string log() const { return log_.str(); }
  /// `ready` (the endpoints matched in time), or a failure that stops the recorder and carries
  /// `what` and its log: ASSERT_TRUE(rec.matched(ready, "recorder did not match")).
  ::testing::AssertionResult matched(bool ready, const std::string& what) {
    if (ready) {
      return ::testing::AssertionSuccess();
    }
    stop();
    return ::testing::AssertionFailure() << what << "\n" << log();
  }

 private:
  RecorderOptions with_log(RecorderOptions o) {
    o.log = &log_;
    return o;
  }
  std::ostringstream log_;  // before recorder_: it writes here
  Recorder recorder_;
  RecorderStats stats_;
  std::thread thread_;
};

}  // namespace poise::record::testing
