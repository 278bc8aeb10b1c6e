// The imu_driver component end to end: a pseudo-terminal device -> driver -> DDS `imu` topic and
// `diagnostics`, received by a subscriber; corrupted lines counted by reason; a disconnect in the
// middle of the stream -> publishing resumes by itself.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <map>
#include <mutex>
#include <regex>
#include <string>
#include <vector>

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include "poise/dds/convert.h"
#include "poise/dds/participant.h"
#include "poise/imu/faults.h"
#include "poise/imu/imu_driver_node.h"
#include "poise/imu/pty_link.h"
#include "poise/runtime/host.h"
#include "poise/testing/testing.h"

namespace poise::imu {
namespace {

using namespace std::chrono_literals;
constexpr auto kWait = 20s;          // bound on every wait (slow, shared CI machines)
constexpr double kValueTol = 1e-5;   // 5 decimals on the wire

RawSample sample(uint32_t seq) {
  RawSample s;
  s.seq = seq;
  s.t_us = 5000u + seq * 2000u;
  s.accel_mps2 = {0.001 * seq, -0.25, 9.8};
  s.gyro_rps = {0.01, 0.002 * (seq % 50), -0.01};
  s.mag_ut = {21.0, -0.5 * (seq % 10), -40.0};
  s.has_pressure = true;
  s.pressure_pa = 100000.0 + seq;
  return s;
}

bool write_all(PtyLink& link, const std::string& data) {
  return poise::testing::wait_until(
      [&] { return link.write(data) == PtyLink::WriteStatus::kWritten; }, 10s);
}

struct Received {
  std::mutex mu;
  std::vector<ImuSample> samples;
  std::map<std::string, uint64_t> counters;  // latest imu_driver diagnostics
  std::size_t count() {
    std::lock_guard<std::mutex> lock(mu);
    return samples.size();
  }
  uint64_t counter(const std::string& name) {
    std::lock_guard<std::mutex> lock(mu);
    const auto it = counters.find(name);
    return it == counters.end() ? 0 : it->second;
  }
};

// One imu_driver component, imu0, reading `port` (reliable `imu`), diagnostics every `period_s`.
runtime::HostSpec driver_host(const std::string& port, const std::string& period_s) {
  auto& registry = runtime::ComponentRegistry::instance();
  if (registry.find("imu_driver") == nullptr) runtime::register_imu_driver(registry);
  return runtime::parse_host(YAML::Load("components: [{type: imu_driver, name: imu0, params: {port: " + port +
                                        ", reliable: true, diagnostics_period_s: " + period_s + "}}]"),
                             "test", ".");
}

TEST(ImuNode, PublishesExactlyTheValidSamplesCountsCorruptionAndSurvivesADisconnect) {
  poise::testing::DomainLease domain;
  const std::string path = ::testing::TempDir() + "poise-imu-node-" + std::to_string(::getpid());
  PtyLink link(path);
  runtime::Host host(driver_host(path, "0.1"), domain.id());
  host.start();

  Received rx;
  dds::Participant participant({domain.id(), "", "", "imu node test"});
  dds::Reader<msg::ImuSamplePubSubType> imu_reader(
      participant, "imu", dds::QosKind::kEstimate, [&](const msg::ImuSample& m, const auto&) {
        std::lock_guard<std::mutex> lock(rx.mu);
        rx.samples.push_back(dds::from_msg(m));
      });
  dds::Reader<msg::FilterDiagnosticsPubSubType> diag_reader(
      participant, "diagnostics", [&](const msg::FilterDiagnostics& m, const auto&) {
        if (m.component_name().to_string() != "imu_driver") return;
        std::lock_guard<std::mutex> lock(rx.mu);
        for (const auto& c : m.counters()) rx.counters[c.name().to_string()] = c.value();
      });
  ASSERT_TRUE(imu_reader.wait_for_writers(1, kWait));
  ASSERT_TRUE(diag_reader.wait_for_writers(1, kWait));

  // Warm-up until the first sample reaches us: the node's writer may match our reader after the
  // reader matched it, and a volatile writer does not resend what it wrote before.
  uint32_t warm = 0;
  ASSERT_TRUE(poise::testing::wait_until(
      [&] {
        if (rx.count() > 0) return true;
        RawSample w = sample(0);
        w.seq = 1000000u + warm;  // the measured stream restarts at 0: a sensor restart (resync)
        w.t_us = 1000u * warm++;
        write_all(link, format_imu_line(w));
        return false;
      },
      kWait));
  poise::testing::sleep_ms(400);  // nothing is written now: diagnostics (every 0.1 s) settle
  const uint64_t warm_samples = rx.counter("samples");  // the driver's count, received or not
  ASSERT_GT(warm_samples, 0u);
  {
    std::lock_guard<std::mutex> lock(rx.mu);
    rx.samples.clear();
  }

  // GIVEN 300 lines, 10 % corrupted by the injector (seeded)
  FaultInjector inj(FaultSpec::parse("garbage=0.02,flip=0.02,truncate=0.02,dup=0.02,nan=0.02,seed=5"));
  std::vector<RawSample> valid;
  for (uint32_t seq = 0; seq < 300; ++seq) {
    const auto before = inj.counts();
    const std::string bytes = inj.apply(format_imu_line(sample(seq)));
    const auto after = inj.counts();
    const auto grew = [&](Fault f) {
      return after[static_cast<std::size_t>(f)] != before[static_cast<std::size_t>(f)];
    };
    if (!grew(Fault::kFlip) && !grew(Fault::kTruncate) && !grew(Fault::kNan)) valid.push_back(sample(seq));
    ASSERT_TRUE(bytes.empty() || write_all(link, bytes));
    // Real-time pace (2 ms of sensor time per line): the reliable keep-last history never overflows.
    poise::testing::sleep_ms(2);
  }
  // THEN exactly the valid samples are published, with their values
  ASSERT_TRUE(poise::testing::wait_until([&] { return rx.count() >= valid.size(); }, kWait))
      << rx.count() << " of " << valid.size() << "; " << host.status().front();
  poise::testing::sleep_ms(200);
  {
    std::lock_guard<std::mutex> lock(rx.mu);
    ASSERT_EQ(rx.samples.size(), valid.size());
    for (std::size_t i = 0; i < valid.size(); ++i) {
      ASSERT_EQ(rx.samples[i].seq, valid[i].seq);
      EXPECT_NEAR(rx.samples[i].accel_mps2.x(), valid[i].accel_mps2.x(), kValueTol);
      EXPECT_NEAR(rx.samples[i].gyro_rps.y(), valid[i].gyro_rps.y(), kValueTol);
      EXPECT_NEAR(rx.samples[i].mag_ut.y(), valid[i].mag_ut.y(), kValueTol);
      EXPECT_TRUE(rx.samples[i].has_pressure);
      if (i > 0) {
        EXPECT_GT(rx.samples[i].stamp_ns, rx.samples[i - 1].stamp_ns);
      }
    }
  }
  // AND the diagnostics count each corrupted line under its reason
  const auto n = [&inj](Fault f) { return inj.counts()[static_cast<std::size_t>(f)]; };
  const uint64_t injected = n(Fault::kGarbage) + n(Fault::kFlip) + n(Fault::kTruncate) +
                            n(Fault::kDup) + n(Fault::kNan);
  ASSERT_GT(injected, 0u);
  ASSERT_TRUE(poise::testing::wait_until(
      [&] {
        return rx.counter("samples") == warm_samples + valid.size() &&
               rx.counter("rejected_total") == injected;
      },
      kWait))
      << "samples " << rx.counter("samples") << ", rejected_total " << rx.counter("rejected_total")
      << " (injected " << injected << ")";
  EXPECT_EQ(rx.counter("rejected_garbage"), n(Fault::kGarbage));
  EXPECT_EQ(rx.counter("rejected_checksum_mismatch"), n(Fault::kFlip));
  EXPECT_EQ(rx.counter("rejected_truncated"), n(Fault::kTruncate));
  EXPECT_EQ(rx.counter("rejected_duplicate_seq"), n(Fault::kDup));
  EXPECT_EQ(rx.counter("rejected_not_finite"), n(Fault::kNan));

  // WHEN the device disappears mid-stream and comes back (rebooted: seq from 0)
  link.disconnect();
  poise::testing::sleep_ms(300);
  link.reconnect();
  for (uint32_t seq = 0; seq < 50; ++seq) {
    ASSERT_TRUE(write_all(link, format_imu_line(sample(seq))));
    poise::testing::sleep_ms(2);
  }
  // THEN publishing resumes by itself
  ASSERT_TRUE(poise::testing::wait_until([&] { return rx.count() == valid.size() + 50; }, kWait))
      << rx.count();
  ASSERT_TRUE(poise::testing::wait_until([&] { return rx.counter("connects") == 2; }, kWait));
  EXPECT_EQ(rx.counter("disconnects"), 1u);
  host.stop();
}

// The status line `poise run` prints next to the filters' (note 10: the driver said 1004 lines
// while the filters had 1201 samples in, its line built at its last diagnostics). Oracle: the
// number of lines written to the port.
uint64_t status_count(const std::string& status, const std::string& what) {
  const std::regex re("([0-9]+) " + what);
  std::smatch m;
  return std::regex_search(status, m, re) ? std::stoull(m[1].str()) : 0;
}

TEST(ImuNode, GivenALongDiagnosticsPeriodWhenLinesArriveThenTheStatusCountsThemWhenPrinted) {
  poise::testing::DomainLease domain;
  const std::string path = ::testing::TempDir() + "poise-imu-status-" + std::to_string(::getpid());
  PtyLink link(path);
  // GIVEN a driver whose diagnostics come once an hour (the first at its first tick)
  runtime::Host host(driver_host(path, "3600"), domain.id());
  host.start();
  ASSERT_TRUE(poise::testing::wait_until(
      [&] { return host.status().front().find("connected") != std::string::npos; }, kWait))
      << host.status().front();
  // WHEN lines arrive after that diagnostics
  constexpr uint64_t kLines = 40;
  for (uint32_t seq = 0; seq < kLines; ++seq) {
    ASSERT_TRUE(write_all(link, format_imu_line(sample(seq))));
    poise::testing::sleep_ms(2);
  }
  // THEN the status counts every one of them, read and published, without waiting for the next
  std::string status;
  EXPECT_TRUE(poise::testing::wait_until(
      [&] {
        status = host.status().front();
        return status_count(status, "lines") == kLines && status_count(status, "samples") == kLines &&
               status_count(status, "published") == kLines;
      },
      kWait))
      << status;
  host.stop();
  // AND once stopped it gives the final counts
  EXPECT_NE(host.status().front().find("final: " + std::to_string(kLines) + " samples read"), std::string::npos)
      << host.status().front();
}

}  // namespace
}  // namespace poise::imu
