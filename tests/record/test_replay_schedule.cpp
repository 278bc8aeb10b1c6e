// Replay timing in simulated time: messages go out at t0 + (log - first) / rate; start/end/topic
// selection; loop; as fast as possible never sleeps.
#include "poise/record/replay_schedule.h"

#include <gtest/gtest.h>

namespace poise::record {
namespace {

constexpr int64_t kMs = 1'000'000;
constexpr int64_t kTimingToleranceNs = 0;  // simulated clock: exact

/// A recording: topic "a" every 10 ms from t=1000 s (log time), "b" every 50 ms; 1 s long.
std::vector<uint8_t> recording() {
  std::vector<uint8_t> buf;
  WriterOptions opt;
  int64_t clock = 0;
  opt.clock = [&clock] { return clock; };
  opt.max_chunk_duration_ns = 100 * kMs;
  McapWriter w(std::make_unique<MemorySink>(buf), opt);
  const uint16_t a = w.add_channel(0, "a", "cdr", {});
  const uint16_t b = w.add_channel(0, "b", "cdr", {});
  const uint64_t t0 = 1000ULL * 1'000'000'000ULL;
  for (int i = 0; i <= 100; ++i) {
    clock = i * 10 * kMs;
    const uint8_t byte = static_cast<uint8_t>(i);
    w.write(a, static_cast<uint32_t>(i), t0 + static_cast<uint64_t>(i) * 10 * kMs, 0, &byte, 1);
    if (i % 5 == 0) {
      w.write(b, static_cast<uint32_t>(i), t0 + static_cast<uint64_t>(i) * 10 * kMs, 0, &byte, 1);
    }
  }
  w.close();
  return buf;
}

struct SimClock {
  int64_t now = 5'000 * kMs;
  int sleeps = 0;
  ReplayClock clock() {
    ReplayClock c;
    c.now_ns = [this] { return now; };
    c.sleep_until_ns = [this](int64_t t) {
      ++sleeps;
      now = std::max(now, t);
    };
    return c;
  }
};

struct Sent {
  std::string topic;
  uint32_t sequence;
  int64_t at_ns;
};

TEST(ReplaySchedule, MessagesGoOutAtRecordedOffsetsScaledByRate) {
  const McapReader reader(std::make_unique<MemorySource>(recording()));
  for (double rate : {1.0, 2.0, 0.5}) {
    SimClock sim;
    const int64_t start = sim.now;
    std::vector<Sent> sent;
    ScheduleOptions opt;
    opt.rate = rate;
    const auto stats = run_schedule(reader, opt, sim.clock(), [&](const MessageView& m) {
      sent.push_back({m.channel->topic, m.sequence, sim.now});
      return true;
    });
    ASSERT_EQ(sent.size(), 101u + 21u);
    EXPECT_EQ(stats.delivered, 122u);
    EXPECT_EQ(stats.passes, 1);
    EXPECT_NEAR(stats.recorded_span_s, 1.0, 1e-9);
    EXPECT_NEAR(stats.elapsed_s, 1.0 / rate, 1e-9);
    for (const Sent& s : sent) {
      const auto expected = start + static_cast<int64_t>(static_cast<double>(s.sequence) * 10.0 *
                                                         kMs / rate);
      EXPECT_NEAR(static_cast<double>(s.at_ns), static_cast<double>(expected),
                  static_cast<double>(kTimingToleranceNs))
          << s.topic << " #" << s.sequence << " rate " << rate;
    }
    EXPECT_EQ(stats.max_late_s, 0.0);
  }
}

TEST(ReplaySchedule, StartEndAndTopicsSelectAndShiftTheTimeline) {
  const McapReader reader(std::make_unique<MemorySource>(recording()));
  SimClock sim;
  const int64_t start = sim.now;
  std::vector<Sent> sent;
  ScheduleOptions opt;
  opt.start_s = 0.2;
  opt.end_s = 0.5;
  opt.topics = {"b"};
  run_schedule(reader, opt, sim.clock(), [&](const MessageView& m) {
    sent.push_back({m.channel->topic, m.sequence, sim.now});
    return true;
  });
  // b every 50 ms: 200, 250, ..., 500 ms -> 7 messages; the first goes out at once.
  ASSERT_EQ(sent.size(), 7u);
  EXPECT_EQ(sent.front().sequence, 20u);
  EXPECT_EQ(sent.back().sequence, 50u);
  EXPECT_EQ(sent.front().at_ns, start);
  EXPECT_EQ(sent.back().at_ns, start + 300 * kMs);
}

TEST(ReplaySchedule, AsFastAsPossibleNeverSleepsAndLoopRepeatsUntilStopped) {
  const McapReader reader(std::make_unique<MemorySource>(recording()));
  SimClock sim;
  ScheduleOptions opt;
  opt.as_fast_as_possible = true;
  opt.loop = true;
  uint64_t count = 0;
  opt.should_stop = [&count] { return count >= 3 * 122; };
  const auto stats = run_schedule(reader, opt, sim.clock(), [&](const MessageView&) {
    ++count;
    return true;
  });
  EXPECT_EQ(sim.sleeps, 0);
  EXPECT_EQ(stats.delivered, 3u * 122u);
  EXPECT_EQ(stats.passes, 3);
}

TEST(ReplaySchedule, StopIsHonouredWhileWaiting) {
  const McapReader reader(std::make_unique<MemorySource>(recording()));
  SimClock sim;
  const int64_t start = sim.now;
  ScheduleOptions opt;
  opt.rate = 0.001;  // 1000 s between the first two messages
  opt.should_stop = [&sim, start] { return sim.now - start > 2'000 * kMs; };
  const auto stats = run_schedule(reader, opt, sim.clock(), [](const MessageView&) { return true; });
  EXPECT_LE(stats.delivered, 2u);
  EXPECT_LT(sim.now - start, 3'000 * kMs);  // polled at least every 100 ms of clock time
}

TEST(ReplaySchedule, RejectsNonPositiveRates) {
  const McapReader reader(std::make_unique<MemorySource>(recording()));
  SimClock sim;
  ScheduleOptions opt;
  opt.rate = 0.0;
  EXPECT_THROW(run_schedule(reader, opt, sim.clock(), [](const MessageView&) { return true; }),
               std::invalid_argument);
}

}  // namespace
}  // namespace poise::record
