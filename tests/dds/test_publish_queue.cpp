// poise::dds::PublishQueue: the producer never waits for a blocked writer; the oldest messages are
// dropped when the queue is full and stale ones are not delivered; every message is accounted for.
// The oracle is arithmetic on what was pushed and what the blocked writer let through.
#include "poise/dds/publish_queue.h"

#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

namespace poise::dds {
namespace {

using namespace std::chrono_literals;

/// A writer that blocks until released (a DDS write stuck on a full socket during a link cut).
struct BlockingWriter {
  std::mutex mutex;
  std::condition_variable cv;
  bool released = false;
  std::atomic<int> entered{0};
  std::vector<int> written;
  bool write(int value) {
    std::unique_lock<std::mutex> lock(mutex);
    entered.fetch_add(1);
    cv.wait(lock, [this] { return released; });
    written.push_back(value);
    return true;
  }
  void release() {
    {
      std::lock_guard<std::mutex> lock(mutex);
      released = true;
    }
    cv.notify_all();
  }
};

void expect_accounted(const PublishQueue<int>::Stats& s) {
  EXPECT_EQ(s.pushed, s.written + s.write_failed + s.dropped_full + s.dropped_stale +
                          s.dropped_at_stop + s.pending);
}

// GIVEN a writer blocked in its first write WHEN 1000 messages are pushed into a queue of 100
// THEN every push returns (the test would hang otherwise), the 899 oldest of those queued after
// the blocked one are dropped and counted, and once released the newest 100 are written in order.
TEST(PublishQueue, PushNeverWaitsForABlockedWriterAndDropsTheOldest) {
  BlockingWriter w;
  constexpr int kPushed = 1000;
  constexpr std::size_t kCapacity = 100;
  PublishQueue<int> q({kCapacity, 0}, [&](const int& v) { return w.write(v); }, [] { return int64_t{0}; });
  q.push(0, 0);
  ASSERT_TRUE(testing::wait_until([&] { return w.entered.load() == 1; }, 10s));
  for (int v = 1; v < kPushed; ++v) {
    q.push(v, 0);
  }
  auto s = q.stats();
  EXPECT_EQ(s.pushed, static_cast<uint64_t>(kPushed));
  EXPECT_EQ(s.dropped_full, static_cast<uint64_t>(kPushed - 1) - kCapacity);
  EXPECT_EQ(s.pending, kCapacity + 1) << "the blocked one plus a full queue";
  expect_accounted(s);
  w.release();
  ASSERT_TRUE(testing::wait_until([&] { return q.stats().pending == 0; }, 10s));
  q.stop();
  s = q.stats();
  EXPECT_EQ(s.written, kCapacity + 1);
  ASSERT_EQ(w.written.size(), kCapacity + 1);
  EXPECT_EQ(w.written.front(), 0);
  for (std::size_t k = 1; k < w.written.size(); ++k) {
    EXPECT_EQ(w.written[k], static_cast<int>(kPushed - kCapacity + k - 1)) << "newest, in order";
  }
  expect_accounted(s);
}

// GIVEN max_age 100 ms and a writer blocked for a while WHEN messages stamped at various times wait
// THEN those older than 100 ms when their turn comes are dropped as stale, the others written.
TEST(PublishQueue, StaleMessagesAreDroppedAndCounted) {
  BlockingWriter w;
  std::atomic<int64_t> now{0};
  constexpr int64_t kMaxAgeNs = 100'000'000;
  PublishQueue<int> q({1000, kMaxAgeNs}, [&](const int& v) { return w.write(v); }, [&] { return now.load(); });
  q.push(0, 0);
  ASSERT_TRUE(testing::wait_until([&] { return w.entered.load() == 1; }, 10s));
  // Stamped 0..900 ms in 100 ms steps; released at t = 1 s: age 1000..100 ms.
  for (int k = 1; k <= 9; ++k) {
    q.push(k, int64_t{k} * 100'000'000);
  }
  now.store(1'000'000'000);
  w.release();
  ASSERT_TRUE(testing::wait_until([&] { return q.stats().pending == 0; }, 10s));
  q.stop();
  const auto s = q.stats();
  // Ages at t = 1 s: k=9 -> 100 ms (not over the limit), k <= 8 -> 200 ms or more (stale).
  EXPECT_EQ(s.dropped_stale, 8U);
  EXPECT_EQ(s.written, 2U);
  ASSERT_EQ(w.written.size(), 2U);
  EXPECT_EQ(w.written[1], 9);
  expect_accounted(s);
}

// GIVEN a writer that never returns within the stop drain time WHEN stop() is called
// THEN it returns once the blocked write ends and the rest of the queue is counted dropped_at_stop.
TEST(PublishQueue, StopIsBoundedAndCountsWhatItDid) {
  BlockingWriter w;
  std::atomic<int64_t> now{0};
  PublishQueue<int> q({100, 0}, [&](const int& v) { return w.write(v); }, [&] { return now.load(); });
  for (int v = 0; v < 50; ++v) {
    q.push(v, 0);
  }
  ASSERT_TRUE(testing::wait_until([&] { return w.entered.load() == 1; }, 10s));
  std::thread stopper([&] { q.stop(); });
  testing::sleep_ms(50);
  now.store(PublishQueue<int>::kStopDrainNs + 1);  // the drain time is over when the write returns
  w.release();
  stopper.join();
  const auto s = q.stats();
  EXPECT_EQ(s.written, 1U);
  EXPECT_EQ(s.dropped_at_stop, 49U);
  expect_accounted(s);
}

}  // namespace
}  // namespace poise::dds
