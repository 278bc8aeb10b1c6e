// A live run (the parallel_kf component on DDS) is recorded; the recording then reproduces the
// live estimates twice: offline with `poise process` (no DDS) and by replaying the IMU topic into
// a fresh parallel_kf component. The input rotates (yaw rate, consistent magnetometer) with
// seeded noise, so a skipped, repeated or reordered sample changes the estimates.
#include "poise/dds/participant.h"
#include "poise/eval/filter_registry.h"
#include "poise/nodes/register.h"
#include "poise/record/mcap.h"
#include "poise/process/process.h"
#include "poise/record/recorder.h"
#include "recorder_thread.h"
#include "poise/record/replayer.h"
#include "poise/runtime/host.h"
#include "record_test_support.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <random>
#include <thread>

namespace poise::record {
namespace {

using namespace std::chrono_literals;
// The default participant profile (multicast discovery on the leased domain): this test creates
// six participants in one process, more than the loopback profile's unicast initial peers cover.
constexpr const char* kProfile = "poise_default";
constexpr auto kMatchTimeout = 30s;  // discovery under a loaded CI machine
constexpr int kSamples = 400;
constexpr int64_t kPeriodNs = 5'000'000;      // 200 Hz
constexpr double kYawRateRps = 0.5;
constexpr double kSameEstimateRad = 1e-9;     // identical inputs -> identical arithmetic
constexpr uint32_t kSeed = 4242;

std::map<int64_t, Eigen::Quaterniond> estimates(const std::string& file, const std::string& topic) {
  std::map<int64_t, Eigen::Quaterniond> out;
  const McapReader reader = McapReader::open_file(file);
  ReadFilter f;
  f.topics = {topic};
  MessageCursor cursor = reader.messages(f);
  while (const MessageView* m = cursor.next()) {
    msg::AttitudeEstimatePubSubType type;
    eprosima::fastrtps::rtps::SerializedPayload_t p(static_cast<uint32_t>(m->size));
    std::memcpy(p.data, m->data, m->size);
    p.length = static_cast<uint32_t>(m->size);
    msg::AttitudeEstimate e;
    if (type.deserialize(&p, &e)) {
      const auto& q = e.q_world_body();
      out[e.header().stamp_ns()] = Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z());
    }
  }
  return out;
}

/// Largest angle between estimates with the same stamp; counts the stamps compared.
double worst_difference(const std::map<int64_t, Eigen::Quaterniond>& a,
                        const std::map<int64_t, Eigen::Quaterniond>& b, size_t* compared) {
  double worst = 0.0;
  *compared = 0;
  for (const auto& [stamp, qa] : a) {
    const auto it = b.find(stamp);
    if (it == b.end()) {
      continue;
    }
    ++*compared;
    worst = std::max(worst, qa.angularDistance(it->second));
  }
  return worst;
}

runtime::HostSpec pkf_host() {
  static const bool registered = [] {
    nodes::register_parallel_kf_node(runtime::ComponentRegistry::instance());
    return true;
  }();
  (void)registered;
  runtime::HostSpec spec;
  spec.participant_profile = kProfile;
  runtime::ComponentSpec c;
  c.type = "parallel_kf";
  c.name = "pkf";
  c.params = YAML::Node(YAML::NodeType::Map);
  c.origin = "test";
  spec.components.push_back(c);
  return spec;
}

TEST(RecordLive, ProcessAndReplayReproduceTheLiveEstimates) {
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("live");
  ASSERT_EQ(::setenv("POISE_QOS_FILE", testing::lossless_profiles(dir).c_str(), 1), 0);
  const std::string live_file = dir + "/live.mcap";
  std::printf("seed %u\n", kSeed);

  // GIVEN a parallel_kf component and a recorder of its input and output
  RecorderOptions ro = testing::recorder_options(live_file, lease.id(), kProfile);
  ro.topics = {"imu", "attitude/parallel_kf"};
  testing::RecorderThread recorder(ro);
  {
    runtime::Host host(pkf_host(), lease.id());
    host.start();
    dds::Participant pub({lease.id(), kProfile, "", "test_imu"});
    dds::Writer<msg::ImuSamplePubSubType> imu(pub, "imu");
    const bool ready = poise::testing::wait_until(
        [&] {
          return recorder->subscribed() == 2 && recorder->matched_writers() >= 2 &&
                 imu.matched() >= 2;
        },
        kMatchTimeout);
    ASSERT_TRUE(recorder.matched(ready, "component/recorder did not match"));
    // WHEN the IMU turns at 0.5 rad/s about up for 2 s (200 Hz, noisy)
    std::mt19937 rng(kSeed);
    for (int i = 0; i < kSamples; ++i) {
      auto m = testing::turning_imu(static_cast<uint32_t>(i), kPeriodNs, kYawRateRps, rng);
      m.valid().pressure(false);
      imu.write(m);
      std::this_thread::sleep_for(std::chrono::nanoseconds(kPeriodNs));
    }
    testing::wait_quiet([&] { return recorder->written(); });
    host.stop();
  }
  RecorderStats rstats = recorder.stop();
  ASSERT_TRUE(rstats.error.empty()) << rstats.error;
  ASSERT_EQ(rstats.topics["imu"].written, static_cast<uint64_t>(kSamples))
      << "the recorder missed IMU samples";
  const auto live = estimates(live_file, "attitude/parallel_kf");
  ASSERT_GT(live.size(), static_cast<size_t>(kSamples / 2)) << recorder.log();

  // THEN `poise process` on the recording gives the live estimates
  {
    std::vector<ProcessFilter> filters;
    filters.push_back({"pkf", eval::make_filter("parallel_kf"), {}});
    ProcessOptions po;
    po.input = live_file;
    po.output = dir + "/processed.mcap";
    process_recording(po, filters);
    const auto processed = estimates(po.output, "processed/attitude/pkf");
    size_t compared = 0;
    const double worst = worst_difference(live, processed, &compared);
    std::printf("process vs live: %zu estimates compared, worst %.3g rad\n", compared, worst);
    EXPECT_EQ(compared, live.size());
    EXPECT_LE(worst, kSameEstimateRad);
    // The comparison is sensitive: another configuration on the same samples differs.
    std::vector<ProcessFilter> other;
    other.push_back({"paper", eval::make_filter("parallel_kf_paper"), {}});
    po.output = dir + "/processed_paper.mcap";
    process_recording(po, other);
    const double other_worst =
        worst_difference(live, estimates(po.output, "processed/attitude/paper"), &compared);
    std::printf("paper configuration vs live: worst %.3g rad\n", other_worst);
    EXPECT_GT(other_worst, 1e3 * kSameEstimateRad);
  }

  // AND replaying the IMU topic into a fresh component gives them again
  {
    const std::string replay_file = dir + "/replayed.mcap";
    RecorderOptions ro2 = ro;
    ro2.output = replay_file;
    ro2.topics = {"attitude/parallel_kf"};
    testing::RecorderThread recorder2(ro2);
    {
      runtime::Host host(pkf_host(), lease.id());
      host.start();
      ReplayOptions po;
      po.input = live_file;
      po.domain = lease.id();
      po.participant_profile = kProfile;
      po.schedule.topics = {"imu"};
      po.wait_for_subscribers_s = 15.0;
      std::ostringstream plog;
      po.log = &plog;
      // Estimates published before recorder2 matches the component's writer would be missed.
      const bool matched = poise::testing::wait_until(
          [&] { return recorder2->subscribed() == 1 && recorder2->matched_writers() >= 1; },
          kMatchTimeout);
      EXPECT_TRUE(matched) << "recorder2 did not match the component's estimate writer";
      if (matched) {
        const ReplayStats ps = replay(po);
        EXPECT_EQ(ps.schedule.delivered, static_cast<uint64_t>(kSamples)) << plog.str();
      }
      testing::wait_quiet([&] { return recorder2->written(); });
      host.stop();
    }
    recorder2.stop();
    const auto replayed = estimates(replay_file, "attitude/parallel_kf");
    size_t compared = 0;
    const double worst = worst_difference(live, replayed, &compared);
    std::printf("replay vs live: %zu estimates compared, worst %.3g rad\n", compared, worst);
    EXPECT_EQ(compared, live.size());
    EXPECT_LE(worst, kSameEstimateRad);
  }
}

}  // namespace
}  // namespace poise::record
