// Framer, sequence/time tracking, clock sync and the driver core, in simulated time.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "poise/imu/driver.h"
#include "poise/imu/faults.h"
#include "poise/imu/framer.h"
#include "poise/imu/timing.h"

namespace poise::imu {
namespace {

constexpr int64_t kNsPerMs = 1000000;

struct Recorder : FrameSink {
  std::vector<std::string> lines;
  std::vector<std::string> infos;
  std::vector<RejectReason> rejects;
  void on_line(std::string_view l) override { lines.emplace_back(l); }
  void on_info(std::string_view t) override { infos.emplace_back(t); }
  void on_reject(RejectReason r, std::size_t) override { rejects.push_back(r); }
};

TEST(ImuFramer, SplitsLinesAcrossArbitraryReadBoundaries) {
  const std::string stream = "$A*41\r\n$IMU,1*00\r\n# hello\r\n\r\n$B*42\n";
  for (std::size_t chunk = 1; chunk <= stream.size(); ++chunk) {
    LineFramer f;
    Recorder r;
    for (std::size_t i = 0; i < stream.size(); i += chunk) {
      f.feed(stream.data() + i, std::min(chunk, stream.size() - i), r);
    }
    ASSERT_EQ(r.lines.size(), 3u) << "chunk " << chunk;
    EXPECT_EQ(r.lines[0], "$A*41\r");
    EXPECT_EQ(r.lines[2], "$B*42");
    ASSERT_EQ(r.infos.size(), 1u);
    EXPECT_EQ(r.infos[0], "# hello");
    EXPECT_TRUE(r.rejects.empty());
  }
}

TEST(ImuFramer, GarbageTruncationAndOverlongAreReported) {
  LineFramer f;
  Recorder r;
  const std::string overlong = "$" + std::string(400, 'x') + "\n";
  const std::string s = "noise\x01\x02$IMU,1,2$A*41\r\n" + overlong + "zz$B*42\r\n$C";
  f.feed(s.data(), s.size(), r);
  f.reset(r);  // disconnect with "$C" pending
  ASSERT_EQ(r.lines.size(), 2u);
  EXPECT_EQ(r.lines[0], "$A*41\r");
  EXPECT_EQ(r.lines[1], "$B*42\r");
  const std::vector<RejectReason> expected{RejectReason::kGarbage, RejectReason::kTruncated,
                                           RejectReason::kOverlong, RejectReason::kGarbage,
                                           RejectReason::kTruncated};
  EXPECT_EQ(r.rejects, expected);
}

TEST(ImuFramer, EndlessNoiseUsesBoundedMemoryAndCountsOneRun) {
  LineFramer f;
  Recorder r;
  const std::string noise(1 << 20, 'n');
  f.feed(noise.data(), noise.size(), r);
  f.feed("\n", 1, r);
  ASSERT_EQ(r.rejects.size(), 1u);
  EXPECT_EQ(r.rejects[0], RejectReason::kGarbage);
}

TEST(ImuSequence, ClassifiesDuplicatesReorderingGapsRestartsAndWraps) {
  SequenceTracker t;
  uint32_t gap = 0;
  EXPECT_EQ(t.check(4294967294u, &gap), SequenceTracker::Verdict::kFirst);
  t.commit(4294967294u);
  EXPECT_EQ(t.check(4294967294u, &gap), SequenceTracker::Verdict::kDuplicate);
  EXPECT_EQ(t.check(4294967290u, &gap), SequenceTracker::Verdict::kOutOfOrder);
  EXPECT_EQ(t.check(1u, &gap), SequenceTracker::Verdict::kNext);  // across the wrap
  EXPECT_EQ(gap, 2u);                                              // ...95 and 0 were lost
  t.commit(1u);
  EXPECT_EQ(t.check(2000000u, &gap), SequenceTracker::Verdict::kRestart);
  t.commit(50000u);
  EXPECT_EQ(t.check(0u, &gap), SequenceTracker::Verdict::kRestart);  // board rebooted
}

TEST(ImuSequence, UnwrapsTheMicrosecondCounter) {
  TimeUnwrapper u;
  u.commit(4294967000u);
  EXPECT_EQ(u.peek_ns(200u), (4294967000LL + 496LL) * 1000);
  u.commit(200u);
  EXPECT_EQ(u.peek_ns(1200u), (4294967496LL + 1000LL) * 1000);
}

// GIVEN a sensor clock with offset and drift and a random transport delay whose minimum is hit
// now and then, WHEN samples stream in, THEN the stamps track the true sampling instants.
TEST(ImuClockSync, RecoversOffsetAndDriftFromNoisyArrivals) {
  const unsigned seed = 20261122;
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::mt19937 rng(seed);
  std::exponential_distribution<double> jitter_ms(1.0 / 2.0);  // mean 2 ms above the minimum
  constexpr double kDriftPpm = 350.0;
  constexpr int64_t kHostAtSensorZeroNs = 5'000'000'000;
  constexpr int64_t kMinDelayNs = 0;
  constexpr double kStampTolMs = 0.3;      // after convergence
  constexpr double kDriftTolPpm = 30.0;
  ClockSync cs;
  int64_t last_stamp = 0;
  double worst_ms = 0;
  for (int k = 0; k < 60000; ++k) {  // 60 s at 1 kHz
    const int64_t sensor_ns = 1'000'000'000LL + static_cast<int64_t>(k) * kNsPerMs;
    const auto truth = kHostAtSensorZeroNs +
                       static_cast<int64_t>(static_cast<double>(sensor_ns) * (1.0 + kDriftPpm * 1e-6));
    const auto arrival = truth + kMinDelayNs + static_cast<int64_t>(jitter_ms(rng) * 1e6);
    const int64_t stamp = cs.update(sensor_ns, arrival);
    ASSERT_LE(stamp, arrival) << "stamp must be causal";
    ASSERT_GT(stamp, last_stamp) << "stamps must increase";
    last_stamp = stamp;
    if (k > 20000) worst_ms = std::max(worst_ms, std::abs(static_cast<double>(stamp - truth)) * 1e-6);
  }
  EXPECT_LT(worst_ms, kStampTolMs);
  EXPECT_NEAR(cs.drift_ppm(), kDriftPpm, kDriftTolPpm);
  EXPECT_EQ(cs.resets(), 0u);
}

TEST(ImuClockSync, RestartsWhenTheSensorClockJumps) {
  ClockSync cs;
  for (int k = 0; k < 3000; ++k) cs.update(k * kNsPerMs, 10'000 * kNsPerMs + k * kNsPerMs);
  // The sensor clock jumps 5 s ahead (e.g. firmware reset of its timer without a seq reset).
  const int64_t stamp = cs.update(8000 * kNsPerMs, 13'001 * kNsPerMs);
  EXPECT_EQ(cs.resets(), 1u);
  EXPECT_LE(stamp, 13'001 * kNsPerMs);
}

// --- driver core ---

RawSample sample(uint32_t seq, uint32_t t_us) {
  RawSample s;
  s.seq = seq;
  s.t_us = t_us;
  s.accel_mps2 = {0.01 * seq, -0.5, 9.81};
  s.gyro_rps = {0.001, 0.002 * (seq % 7), -0.003};
  s.mag_ut = {20.0, -5.0, -42.0 + 0.1 * (seq % 13)};
  s.has_pressure = true;
  s.pressure_pa = 100000.0 + seq;
  return s;
}

TEST(ImuDriver, ValidLinesMixedWithCorruptOnesGiveExactlyTheValidSamples) {
  // GIVEN 500 valid lines interleaved with one corrupted line of each kind, fed in random chunks
  const unsigned seed = 7;
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::mt19937 rng(seed);
  std::string stream;
  std::vector<RawSample> expected;
  constexpr int kValid = 500;
  for (int i = 0; i < kValid; ++i) {
    const RawSample s = sample(static_cast<uint32_t>(i), static_cast<uint32_t>(i) * 1000u);
    stream += format_imu_line(s);
    expected.push_back(s);
    switch (i) {
      case 10: stream += "\x07garbage!!\r\n"; break;
      case 20: { std::string l = format_imu_line(sample(999, 1)); l[10] ^= 0x04; stream += l; break; }
      case 30: stream += format_imu_line(sample(30, 30000)); break;                    // duplicate
      case 40: stream += format_imu_line(sample(35, 35000)); break;                    // reordered
      case 50: stream += format_imu_line(sample(51, 40000)); break;                    // t backwards
      case 60: stream += "$IMU,61,61000,0,0,9.8"; break;                              // truncated
      case 70: stream += wrap_payload("IMU,71,71000,0,0,nan,0,0,0,1,2,3,,"); break;
      case 80: stream += wrap_payload("IMU,81,81000,0,0,999,0,0,0,1,2,3,,"); break;
      case 90: stream += wrap_payload("IMU,91,91000,0,0,9.8,0,0,x,1,2,3,,"); break;
      case 100: stream += "$" + std::string(300, '1') + "\r\n"; break;
      default: break;
    }
  }
  std::vector<ImuSample> out;
  std::vector<SampleInfo> infos;
  ImuDriver drv({}, {}, [&](const ImuSample& s, const SampleInfo& i) {
    out.push_back(s);
    infos.push_back(i);
  });
  std::uniform_int_distribution<std::size_t> chunk(1, 200);
  int64_t now = 0;
  for (std::size_t i = 0; i < stream.size();) {
    const std::size_t n = std::min(chunk(rng), stream.size() - i);
    now += static_cast<int64_t>(n) * 20000;  // 50 bytes/ms: the link is never ahead of the sensor
    drv.feed(stream.data() + i, n, now);
    i += n;
  }
  // THEN exactly the valid samples come out, in order, with their values
  ASSERT_EQ(out.size(), expected.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(out[i].seq, expected[i].seq);
    EXPECT_NEAR(out[i].accel_mps2.x(), expected[i].accel_mps2.x(), 1e-5);
    EXPECT_NEAR(out[i].mag_ut.z(), expected[i].mag_ut.z(), 1e-5);
    EXPECT_NEAR(out[i].pressure_pa, expected[i].pressure_pa, 0.05);
    if (i > 0) {
      EXPECT_GT(out[i].stamp_ns, out[i - 1].stamp_ns);
    }
    // Causal; lines of one read clamped to its arrival are spread by 1 ns each to stay increasing.
    constexpr int64_t kClampTolNs = 100;
    EXPECT_LE(out[i].stamp_ns, infos[i].arrival_ns + kClampTolNs);
  }
  // AND each corrupted line is counted once under its reason, nothing is lost by sequence gap
  const DriverStats& st = drv.stats();
  const auto count = [&st](RejectReason r) { return st.rejects[static_cast<std::size_t>(r)]; };
  EXPECT_EQ(count(RejectReason::kGarbage), 1u);
  EXPECT_EQ(count(RejectReason::kChecksumMismatch), 1u);
  EXPECT_EQ(count(RejectReason::kDuplicateSeq), 1u);
  EXPECT_EQ(count(RejectReason::kOutOfOrderSeq), 1u);
  EXPECT_EQ(count(RejectReason::kTimeNotMonotonic), 1u);
  EXPECT_EQ(count(RejectReason::kTruncated), 1u);
  EXPECT_EQ(count(RejectReason::kNotFinite), 1u);
  EXPECT_EQ(count(RejectReason::kOutOfRange), 1u);
  EXPECT_EQ(count(RejectReason::kNonNumeric), 1u);
  EXPECT_EQ(count(RejectReason::kOverlong), 1u);
  EXPECT_EQ(st.samples, static_cast<uint64_t>(kValid));
}

TEST(ImuDriver, CountsSequenceGapsAndResyncsAfterReconnect) {
  std::vector<ImuSample> out;
  ImuDriver drv({}, {}, [&](const ImuSample& s, const SampleInfo&) { out.push_back(s); });
  int64_t now = 1'000'000'000;
  for (uint32_t seq : {0u, 1u, 2u, 5u, 6u}) {  // 3 and 4 lost
    now += kNsPerMs;
    drv.feed(format_imu_line(sample(seq, seq * 1000u)), now);
  }
  EXPECT_EQ(drv.stats().seq_gap_drops, 2u);
  drv.feed("$IMU,7,70", now);  // cable pulled mid-line
  drv.reset();
  EXPECT_EQ(drv.stats().rejects[static_cast<std::size_t>(RejectReason::kTruncated)], 1u);
  // The board rebooted: seq and clock restart from zero.
  for (uint32_t seq : {0u, 1u, 2u}) {
    now += kNsPerMs;
    drv.feed(format_imu_line(sample(seq, 500u + seq * 1000u)), now);
  }
  ASSERT_EQ(out.size(), 8u);
  EXPECT_EQ(out.back().seq, 2u);
  EXPECT_GT(out[5].stamp_ns, out[4].stamp_ns);
  EXPECT_EQ(drv.stats().seq_gap_drops, 2u);
  EXPECT_EQ(drv.stats().disconnects, 1u);
}

// Issue 33: a firmware whose t_us advances at a tenth of real time (the wrong unit) made the driver
// drop 45 % of its samples as "stale" with no word about the clock. The driver measures the
// sensor clock against the arrivals and names the ratio. Oracle: the ratio the test feeds.
TEST(ImuDriver, GivenASensorClockAtATenthOfRealTimeThenTheRatioIsMeasuredAndNamed) {
  constexpr double kRatioTolerance = 0.01;  // dimensionless, over a 5 s window of 10 ms steps
  const auto run = [](uint32_t t_step_us) {
    ImuDriver drv({}, {}, [](const ImuSample&, const SampleInfo&) {});
    int64_t now = 1'000'000'000;
    for (uint32_t seq = 0; seq < 1200; ++seq) {  // 12 s at 100 Hz
      now += 10 * kNsPerMs;
      drv.feed(format_imu_line(sample(seq, 1000u + seq * t_step_us)), now);
    }
    return drv.stats();
  };
  const DriverStats slow = run(1000);  // 1 ms of sensor time per 10 ms line
  EXPECT_NEAR(slow.clock_ratio, 0.1, kRatioTolerance);
  const std::string problem = clock_ratio_problem(slow);
  EXPECT_NE(problem.find("the sensor clock advances at 0.10 x host time (t_us +0.50 s in 5.00 s of arrivals): is "
                         "the firmware's t_us in microseconds?"),
            std::string::npos)
      << problem;
  const DriverStats normal = run(10000);
  EXPECT_NEAR(normal.clock_ratio, 1.0, kRatioTolerance);
  EXPECT_EQ(clock_ratio_problem(normal), "");
}

TEST(ImuDriver, RejectsSensorTimeGoingBackwardsWhileSeqAdvances) {
  std::vector<ImuSample> out;
  ImuDriver drv({}, {}, [&](const ImuSample& s, const SampleInfo&) { out.push_back(s); });
  drv.feed(format_imu_line(sample(1, 5000)), 1);
  drv.feed(format_imu_line(sample(2, 4000)), 2);
  drv.feed(format_imu_line(sample(3, 6000)), 3);
  EXPECT_EQ(out.size(), 2u);
  EXPECT_EQ(drv.stats().rejects[static_cast<std::size_t>(RejectReason::kTimeNotMonotonic)], 1u);
}

// Issue 19 item 4: the sensor clock jumps while seq keeps counting. Oracle: the documented rule:
// reanchor_samples (3) consecutive agreeing lines restart the time base at the last of them, the
// ones before are rejected as time_not_monotonic, every later line is published, stamps rise.
void expect_recovers_from_clock_jump(uint32_t t_before_us, uint32_t t_after_us) {
  std::vector<ImuSample> out;
  ImuDriver drv({}, {}, [&](const ImuSample& s, const SampleInfo&) { out.push_back(s); });
  constexpr uint32_t kPeriodUs = 10000;  // 100 Hz
  int64_t now = 1'000'000'000;
  uint32_t seq = 0;
  for (int i = 0; i < 50; ++i, ++seq) {
    now += 10 * kNsPerMs;
    drv.feed(format_imu_line(sample(seq, t_before_us + static_cast<uint32_t>(i) * kPeriodUs)), now);
  }
  for (int i = 0; i < 200; ++i, ++seq) {  // the clock jumped; seq counts on
    now += 10 * kNsPerMs;
    drv.feed(format_imu_line(sample(seq, t_after_us + static_cast<uint32_t>(i) * kPeriodUs)), now);
  }
  const auto not_monotonic = drv.stats().rejects[static_cast<std::size_t>(RejectReason::kTimeNotMonotonic)];
  EXPECT_EQ(not_monotonic, 2u);                 // reanchor_samples - 1
  EXPECT_EQ(drv.stats().clock_reanchors, 1u);
  ASSERT_EQ(out.size(), 250u - 2u);
  EXPECT_EQ(out.back().seq, seq - 1);
  for (size_t k = 1; k < out.size(); ++k) {
    ASSERT_GT(out[k].stamp_ns, out[k - 1].stamp_ns) << k;
  }
}

TEST(ImuDriver, GivenTheSensorClockJumpsBackWhileSeqCountsThenThreeAgreeingLinesRestartTheTimeBase) {
  expect_recovers_from_clock_jump(900'000'000u, 1'000u);
}

TEST(ImuDriver, GivenTheSensorClockJumpsForwardBy2To31UsOrMoreThenItRecoversTheSameWay) {
  constexpr uint32_t kLastBeforeUs = 1'000u + 49u * 10'000u;  // t_us of the last line before the jump
  expect_recovers_from_clock_jump(1'000u, kLastBeforeUs + (1u << 31));  // exactly 2^31 us ahead
  expect_recovers_from_clock_jump(1'000u, 4'000'000'000u);
}

TEST(ImuDriver, GivenOneWildClockValueThenOnlyThatLineIsLostAndTheTimeBaseStays) {
  std::vector<ImuSample> out;
  ImuDriver drv({}, {}, [&](const ImuSample& s, const SampleInfo&) { out.push_back(s); });
  int64_t now = 1'000'000'000;
  for (uint32_t seq = 0; seq < 20; ++seq) {
    now += 10 * kNsPerMs;
    const uint32_t t_us = seq == 10 ? 5u : 100'000u + seq * 10'000u;  // one wild t_us
    drv.feed(format_imu_line(sample(seq, t_us)), now);
  }
  EXPECT_EQ(out.size(), 19u);
  EXPECT_EQ(drv.stats().rejects[static_cast<std::size_t>(RejectReason::kTimeNotMonotonic)], 1u);
  EXPECT_EQ(drv.stats().clock_reanchors, 0u);
}

TEST(ImuClockJumpAnchor, RequiresConsecutiveSeqAndForwardTimeWithinTheBound) {
  ClockJumpAnchor a(3, 1.0, 100);
  EXPECT_FALSE(a.refused(10, 1000));
  EXPECT_FALSE(a.refused(11, 2000));
  EXPECT_TRUE(a.refused(12, 3000));        // third agreeing line
  EXPECT_FALSE(a.refused(13, 4000));       // a new run starts
  EXPECT_FALSE(a.refused(14, 3500));       // time back: run restarts at this line
  EXPECT_FALSE(a.refused(15, 3500 + 2'000'000));  // 2 s for one seq step > 1 s: disagrees
  EXPECT_FALSE(a.refused(16, 3500 + 2'010'000));
  EXPECT_TRUE(a.refused(17, 3500 + 2'020'000));
  a.clear();
  EXPECT_FALSE(a.refused(18, 10));
  EXPECT_FALSE(a.refused(500, 20));        // seq jumped beyond the step bound
}

TEST(ImuDriver, InfoLinesAreKeptAndNotCountedAsRejects) {
  ImuDriver drv({}, {}, nullptr);
  drv.feed("# gy87_poise v1 ready\r\n", 1);
  EXPECT_EQ(drv.stats().info_lines, 1u);
  EXPECT_EQ(drv.stats().last_info, "# gy87_poise v1 ready");
  EXPECT_EQ(drv.stats().rejected_total(), 0u);
}

TEST(ImuDriver, TransmissionTimeIsRemovedFromArrival) {
  // GIVEN 115200 baud (11520 bytes/s) and arrivals exactly at the end of each line
  DriverParams p;
  p.link_bytes_per_s = 11520.0;
  std::vector<ImuSample> out;
  std::vector<SampleInfo> infos;
  ImuDriver drv(p, {}, [&](const ImuSample& s, const SampleInfo& i) {
    out.push_back(s);
    infos.push_back(i);
  });
  const int64_t host_at_zero = 3'000'000'000;
  for (uint32_t k = 0; k < 100; ++k) {
    const std::string l = format_imu_line(sample(k, k * 10000u));
    const auto tx_ns = static_cast<int64_t>(static_cast<double>(l.size()) / 11520.0 * 1e9);
    drv.feed(l, host_at_zero + static_cast<int64_t>(k) * 10 * kNsPerMs + tx_ns);
  }
  // THEN stamps are the sampling instants (to within a byte time, 87 us)
  constexpr double kTolNs = 100e3;
  for (std::size_t k = 0; k < out.size(); ++k) {
    EXPECT_NEAR(static_cast<double>(out[k].stamp_ns),
                static_cast<double>(host_at_zero + static_cast<int64_t>(k) * 10 * kNsPerMs), kTolNs);
  }
}

TEST(ImuRateLatencyMeter, ReportsRateAndPercentiles) {
  RateLatencyMeter m(1.0);
  for (int k = 0; k < 1000; ++k) {
    const int64_t arrival = 10'000'000'000 + k * kNsPerMs;
    m.add(arrival - (k % 100 == 0 ? 20 : 2) * kNsPerMs, arrival);
  }
  const auto s = m.summarize(10'000'000'000 + 999 * kNsPerMs);
  EXPECT_NEAR(s.rate_hz, 1000.0, 1.0);
  EXPECT_NEAR(s.latency_p50_ms, 2.0, 1e-9);
  EXPECT_NEAR(s.latency_max_ms, 20.0, 1e-9);
}

// Issue 33: `sim-imu --faults flip=nan` was accepted (a NaN probability passes every range
// comparison). Non-finite and out-of-range values are refused with a message naming the key.
TEST(FaultSpecParse, GivenNonFiniteOrOutOfRangeValuesWhenParsedThenRefusedNamingTheKey) {
  struct Case {
    const char* spec;
    const char* expected;  // part of the message
  };
  const Case cases[] = {
      {"flip=nan", "'flip=nan': flip must be a finite number, not 'nan'"},
      {"drop=inf", "'drop=inf': drop must be a finite number, not 'inf'"},
      {"garbage=-nan", "garbage must be a finite number"},
      {"disconnect=inf:1", "disconnect must be a finite number"},
      {"seed=nan", "seed must be a finite number"},
      {"seed=-1", "'seed=-1': seed must be an integer in [0, 4294967295]"},
      {"seed=1e20", "seed must be an integer"},
      {"seed=1.5", "seed must be an integer"},
      {"flip=1.5", "'flip=1.5': probability must be in [0, 1]"},
  };
  for (const Case& c : cases) {
    try {
      (void)FaultSpec::parse(c.spec);
      ADD_FAILURE() << c.spec << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(c.expected), std::string::npos) << c.spec << ": " << e.what();
    }
  }
  const FaultSpec ok = FaultSpec::parse("flip=0.25,seed=4294967295");
  EXPECT_EQ(ok.seed, 4294967295u);
  EXPECT_DOUBLE_EQ(ok.probability[static_cast<size_t>(Fault::kFlip)], 0.25);
}

}  // namespace
}  // namespace poise::imu
