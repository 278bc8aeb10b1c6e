// PublishQueue: publishing that never stalls the producer. A producer (e.g. the thread reading a
// serial port) push()es messages into a bounded queue and returns at once; a writer thread of the
// queue takes them and calls `write`, which may block (a DDS write whose socket buffer is full
// while a link is down blocked for seconds in Fast DDS 2.9, issue 22). Policy, explicit and
// counted (docs/NETWORK.md "The sensor path never blocks"):
//   - queue full: the OLDEST queued message is dropped (dropped_full) so the newest data goes out;
//   - stale: a message whose age (now - stamp) exceeds max_age_ns when its turn comes is dropped
//     (dropped_stale) instead of being delivered late; max_age_ns 0 disables the check.
//   - stop: what is queued is still written for up to kStopDrainNs, the rest is dropped
//     (dropped_at_stop), so stopping is bounded even while writes block.
// Every message pushed is exactly one of: written, write_failed, dropped_full, dropped_stale,
// dropped_at_stop, or still queued (pending) -- stats() adds up. Thread-safe; the clock is injected (adapters only).
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>

namespace poise::dds {

template <class Message>
class PublishQueue {
 public:
  struct Options {
    std::size_t capacity = 256;  ///< messages queued at most (>= 1)
    int64_t max_age_ns = 0;      ///< drop messages older than this when they are due; 0 = never
  };
  struct Stats {
    uint64_t pushed = 0;
    uint64_t written = 0;       ///< write() returned true
    uint64_t write_failed = 0;  ///< write() returned false
    uint64_t dropped_full = 0;  ///< oldest dropped because the queue was full
    uint64_t dropped_stale = 0; ///< older than max_age when due
    uint64_t dropped_at_stop = 0;  ///< still queued when stop()'s drain time ran out
    uint64_t pending = 0;       ///< in the queue now
    uint64_t high_water = 0;    ///< most messages ever queued at once
    int64_t longest_write_ns = 0;
    uint64_t slow_writes = 0;   ///< write() calls that took over 1 ms
  };
  static constexpr int64_t kStopDrainNs = 1'000'000'000;
  using Write = std::function<bool(const Message&)>;
  using Clock = std::function<int64_t()>;

  /// Starts the writer thread. `write` runs on it only; `now_ns` gives the clock of the stamps.
  PublishQueue(Options options, Write write, Clock now_ns)
      : options_(options), write_(std::move(write)), now_ns_(std::move(now_ns)) {
    if (options_.capacity == 0) {
      options_.capacity = 1;
    }
    thread_ = std::thread([this] { run(); });
  }
  ~PublishQueue() { stop(); }
  PublishQueue(const PublishQueue&) = delete;
  PublishQueue& operator=(const PublishQueue&) = delete;

  /// Queues `message` stamped `stamp_ns` (same clock as now_ns); never blocks on the writer.
  void push(Message message, int64_t stamp_ns) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++stats_.pushed;
      if (queue_.size() >= options_.capacity) {
        queue_.pop_front();
        ++stats_.dropped_full;
      }
      queue_.emplace_back(stamp_ns, std::move(message));
      stats_.high_water = std::max<uint64_t>(stats_.high_water, queue_.size());
    }
    cv_.notify_one();
  }

  /// Writes what is queued (bounded by the writer's own pace) and stops the thread. Idempotent.
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!stopping_) {
        stopping_ = true;
        stop_deadline_ns_ = now_ns_() + kStopDrainNs;
      }
    }
    cv_.notify_all();
    if (thread_.joinable()) {
      thread_.join();
    }
  }

  [[nodiscard]] Stats stats() const {
    std::lock_guard<std::mutex> lock(mutex_);
    Stats s = stats_;
    s.pending = queue_.size() + (in_write_ ? 1U : 0U);
    return s;
  }

 private:
  void run() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      cv_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) {
        return;  // stopping and drained
      }
      if (stopping_ && now_ns_() > stop_deadline_ns_) {
        stats_.dropped_at_stop += queue_.size();
        queue_.clear();
        return;
      }
      auto [stamp_ns, message] = std::move(queue_.front());
      queue_.pop_front();
      if (options_.max_age_ns > 0 && now_ns_() - stamp_ns > options_.max_age_ns) {
        ++stats_.dropped_stale;
        continue;
      }
      in_write_ = true;
      lock.unlock();
      const int64_t t0 = now_ns_();
      const bool ok = write_(message);
      const int64_t took = now_ns_() - t0;
      lock.lock();
      in_write_ = false;
      ++(ok ? stats_.written : stats_.write_failed);
      stats_.longest_write_ns = std::max(stats_.longest_write_ns, took);
      stats_.slow_writes += took > 1'000'000 ? 1U : 0U;
    }
  }

  Options options_;
  Write write_;
  Clock now_ns_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::pair<int64_t, Message>> queue_;
  Stats stats_;
  bool in_write_ = false;
  bool stopping_ = false;
  int64_t stop_deadline_ns_ = 0;
  std::thread thread_;
};

}  // namespace poise::dds
