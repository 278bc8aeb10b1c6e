// Tools that never trust the wire (issue 19, item 2): a peer publishes malformed payloads under
// the ImuSample type name with no key hash (`poise dds-test-pub --type imu-malformed`: every
// valid sample followed by one of schema::malformed_variants(), reliable). `poise record`,
// `poise echo` and `poise topics` keep running, count the malformed payloads and keep every valid
// one. Children on an exclusive loopback domain; every wait bounded.
#include "poise/schema/cdr.h"
#include "poise/schema/malformed.h"
#include "poise/record/mcap.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>
#include <poise/msg/imuPubSubTypes.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <regex>
#include <set>
#include <string>
#include <vector>

namespace {

using namespace std::chrono_literals;
using poise::testing::Child;
using poise::testing::DomainLease;
using poise::testing::run;

const std::vector<std::string> kEnv = {"POISE_DDS_PROFILE=poise_loopback"};
constexpr auto kCommandTimeout = 30s;  // bound on each CLI run (discovery included)
constexpr auto kExitTimeout = 15s;     // a stopped child finalises and exits within this
constexpr int kPairs = 24;  // valid + malformed samples published; 2 cycles of the variants

std::vector<std::string> malformed_pub(int domain, int count, double rate_hz,
                                       const std::string& type = "imu-malformed") {
  return {poise::testing::bin("poise"), "dds-test-pub", "--type", type, "--domain",
          std::to_string(domain), "--count", std::to_string(count), "--rate",
          std::to_string(rate_hz), "--wait-readers", "20"};
}

std::string temp_dir(const std::string& name) {
  const std::string dir = std::string(std::getenv("TMPDIR") != nullptr ? std::getenv("TMPDIR")
                                                                        : "/tmp") +
                          "/poise-hostile-" + name + "-" + std::to_string(::getpid());
  EXPECT_EQ(std::system(("rm -rf '" + dir + "' && mkdir -p '" + dir + "'").c_str()), 0);
  return dir;
}

TEST(HostileWire, GivenMalformedVariantsWhenCheckedThenEveryOneIsAProblemAndTheOriginalIsNot) {
  const auto& table = poise::schema::TypeTable::builtin();
  poise::msg::ImuSample m;
  m.header().frame_id("body");
  m.sensor_id("imu0");
  poise::msg::ImuSamplePubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.m_typeSize);
  ASSERT_TRUE(type.serialize(&m, &payload));
  const std::vector<std::uint8_t> full(payload.data, payload.data + payload.length);
  ASSERT_EQ(poise::schema::payload_problem(table, "poise::msg::ImuSample", full.data(), full.size()),
            std::nullopt);
  const auto variants = poise::schema::malformed_variants(full);
  EXPECT_EQ(variants.size(), 12U);
  for (const auto& v : variants) {
    EXPECT_NE(poise::schema::payload_problem(table, "poise::msg::ImuSample", v.bytes.data(),
                                               v.bytes.size()),
              std::nullopt)
        << v.name;
  }
}

TEST(HostileWire, GivenMalformedImuSamplesWhenRecordedThenEveryValidOneIsKeptAndTheRestCounted) {
  DomainLease lease;
  const std::string dir = temp_dir("record");
  const std::string file = dir + "/hostile.mcap";
  Child recorder({poise::testing::bin("poise"), "record", "imu", "-o", file, "--domain",
                  std::to_string(lease.id())},
                 kEnv);
  const auto pub = run(malformed_pub(lease.id(), kPairs, 100.0), kCommandTimeout, kEnv);
  ASSERT_EQ(pub.exit_code, 0) << pub.output << "\nrecorder:\n" << recorder.output();
  ASSERT_NE(pub.output.find("published " + std::to_string(kPairs) + " valid, " +
                            std::to_string(kPairs) + " malformed"),
            std::string::npos)
      << pub.output;
  // Reliable + acknowledged: everything has reached the recorder's reader. The recorder writes
  // its queue every 100 ms; stop it after that and let it finalise.
  poise::testing::sleep_ms(500);
  recorder.signal(SIGINT);
  const auto code = recorder.wait_for(kExitTimeout);
  ASSERT_TRUE(code.has_value()) << recorder.output();
  ASSERT_EQ(*code, 0) << "the recorder must survive malformed payloads\n" << recorder.output();
  const std::string out = recorder.output();
  EXPECT_NE(out.find("imu (poise::msg::ImuSample): received " + std::to_string(2 * kPairs) +
                     ", written " + std::to_string(kPairs) + ", malformed " +
                     std::to_string(kPairs) + ", dropped 0, lost 0"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("malformed payloads were rejected, not recorded (first: "), std::string::npos)
      << out;

  const auto reader = poise::record::McapReader::open_file(file);
  EXPECT_TRUE(reader.report().complete) << "the recording is finalised";
  std::set<std::int64_t> seqs;
  auto cursor = reader.messages();
  while (const auto* m = cursor.next()) {
    const auto v = poise::schema::decode(poise::schema::TypeTable::builtin(),
                                           "poise::msg::ImuSample", m->data, m->size);
    seqs.insert(static_cast<std::int64_t>(v.at("header.seq")->u));
  }
  EXPECT_EQ(seqs.size(), static_cast<size_t>(kPairs));
  EXPECT_EQ(*seqs.begin(), 0);
  EXPECT_EQ(*seqs.rbegin(), kPairs - 1);
}

TEST(HostileWire, GivenMalformedImuSamplesWhenEchoedThenValidOnesPrintAndMalformedOnesAreCounted) {
  DomainLease lease;
  // Echo reads best-effort: it waits for half the valid samples, so a lost one cannot hang it.
  Child echo({poise::testing::bin("poise"), "echo", "imu", "--json", "--count",
              std::to_string(kPairs / 2), "--domain", std::to_string(lease.id()), "--timeout",
              "20"},
             kEnv);
  const auto pub = run(malformed_pub(lease.id(), kPairs, 100.0), kCommandTimeout, kEnv);
  ASSERT_EQ(pub.exit_code, 0) << pub.output << "\necho:\n" << echo.output();
  const auto code = echo.wait_for(kExitTimeout);
  ASSERT_TRUE(code.has_value()) << echo.output();
  ASSERT_EQ(*code, 0) << "echo must survive malformed payloads\n" << echo.output();
  const std::string out = echo.output();
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      out, m, std::regex(R"((\d+) sample\(s\) printed, (\d+) lost on the way \(.*?\), (\d+) malformed rejected)")))
      << out;
  EXPECT_EQ(std::stoi(m[1]), kPairs / 2) << out;
  // a malformed payload's header.seq is not a gap: at most the valid samples sent can be lost
  EXPECT_LE(std::stoll(m[2]), kPairs) << out;
  EXPECT_GE(std::stoi(m[3]), 1) << out;
  EXPECT_NE(out.find("poise echo: malformed sample of "), std::string::npos) << out;
  int printed = 0;
  for (size_t at = out.find("{\"topic\":\"imu\""); at != std::string::npos;
       at = out.find("{\"topic\":\"imu\"", at + 1)) {
    ++printed;
  }
  EXPECT_EQ(printed, kPairs / 2) << out;
}

TEST(HostileWire, GivenMalformedImuSamplesWhenTopicsSamplesThemThenTheyAreCountedAsMalformed) {
  DomainLease lease;
  Child pub(malformed_pub(lease.id(), 1000, 100.0), kEnv);
  const auto r = run({poise::testing::bin("poise"), "topics", "--json", "--duration", "4",
                      "--domain", std::to_string(lease.id())},
                     kCommandTimeout, kEnv);
  ASSERT_EQ(r.exit_code, 0) << r.output << "\npublisher:\n" << pub.output();
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      r.output, m,
      std::regex(R"re(\{"topic":"imu","type":"poise::msg::ImuSample","writers":1,"samples":(\d+),.*"malformed":(\d+),"lost":(\d+|null)\})re")))
      << r.output << "\npublisher:\n" << pub.output();
  EXPECT_GE(std::stoi(m[1]), 1) << r.output;
  EXPECT_GE(std::stoi(m[2]), 1) << r.output;
}

/// Runs `poise <command>` on a fresh domain while `dds-test-pub --type <pub_type>` publishes
/// `count` valid samples each followed by a malformed one; the node must keep running and exit 0
/// on SIGINT. Returns the last match of `status` in its output (empty after a failed assertion).
std::smatch run_node_against_malformed(const std::string& command, const std::string& pub_type, int count,
                                       const std::regex& status, std::string& out) {
  std::smatch m;
  DomainLease lease;
  Child node({poise::testing::bin("poise"), command, "--domain", std::to_string(lease.id()),
              "--status-period", "0.5"},
             kEnv);
  const auto pub = run(malformed_pub(lease.id(), count, 100.0, pub_type), kCommandTimeout, kEnv);
  out = node.output();
  EXPECT_EQ(pub.exit_code, 0) << pub.output << "\nnode:\n" << out;
  if (pub.exit_code != 0) return m;
  poise::testing::sleep_ms(1500);  // at least two status lines after the last sample
  const bool running = !node.wait_for(0ms).has_value();
  EXPECT_TRUE(running) << "the node must keep running\n" << node.output();
  node.signal(SIGINT);
  const auto code = node.wait_for(kExitTimeout);
  out = node.output();
  EXPECT_TRUE(code.has_value()) << out;
  if (!running || !code.has_value()) return m;
  EXPECT_EQ(*code, 0) << out;
  for (auto it = std::sregex_iterator(out.begin(), out.end(), status); it != std::sregex_iterator(); ++it) {
    m = *it;  // the last status line
  }
  EXPECT_FALSE(m.empty()) << out;
  return m;
}

// The estimator nodes read with the generated type support (poise::dds::Reader): an unknown
// encapsulation used to escape fastcdr as BadParamException and terminate the process. Each node
// (`poise <command>`) gets 4 x kPairs valid samples (level, facing magnetic north, with pressure:
// every node can use them), each followed by a malformed one. It must keep running, count the
// malformed payloads in its status and diagnostics, and publish estimates from the valid
// samples that follow the malformed ones.
void expect_node_survives_malformed_imu(const std::string& command) {
  constexpr int kValid = 4 * kPairs;
  std::string out;
  // The samples' stamps advance as they are sent (dds-test-pub): none is stale on arrival.
  const std::regex status(R"(imu in (\d+), estimates out (\d+), rejected (\d+), stale 0, malformed (\d+))");
  const std::smatch m = run_node_against_malformed(command, "imu-malformed", kValid, status, out);
  if (m.empty()) return;
  const int in = std::stoi(m[1]);
  const int estimates = std::stoi(m[2]);
  const int malformed = std::stoi(m[4]);
  std::printf("%s: imu in %d, estimates out %d, rejected %s, malformed %d of %d + %d published\n",
              command.c_str(), in, estimates, m[3].str().c_str(), malformed, kValid, kValid);
  // Best-effort sensor QoS: not every sample need arrive, but both kinds must be seen; payloads
  // fastcdr still accepts (a frame_id without NUL, trailing bytes) count as received (and are
  // then refused by the core: their stamp repeats the valid sample's).
  EXPECT_GE(malformed, 1) << out;
  EXPECT_LE(in + malformed, 2 * kValid) << out;
  EXPECT_EQ(in, estimates + std::stoi(m[3])) << "every received sample estimated or rejected\n" << out;
  // Estimates from the valid samples, most of which follow a malformed one (loopback: a quarter
  // is a generous floor; measured: all of them)
  EXPECT_GE(estimates, kValid / 4) << out;
}

TEST(HostileWire, GivenMalformedImuSamplesWhenAParallelKfNodeReadsThemThenItKeepsRunningCountsAndEstimates) {
  expect_node_survives_malformed_imu("parallel-kf");
}

TEST(HostileWire, GivenMalformedImuSamplesWhenASelectiveEkfNodeReadsThemThenItKeepsRunningCountsAndEstimates) {
  expect_node_survives_malformed_imu("selective-ekf");
}

TEST(HostileWire, GivenMalformedImuSamplesWhenAGaussNewtonNodeReadsThemThenItKeepsRunningCountsAndEstimates) {
  expect_node_survives_malformed_imu("gauss-newton");
}

TEST(HostileWire, GivenMalformedImuSamplesWhenAnAltitudeNodeReadsThemThenItKeepsRunningCountsAndEstimates) {
  expect_node_survives_malformed_imu("altitude");
}

TEST(HostileWire, GivenMalformedImuSamplesWhenAVehicleNodeReadsThemThenItKeepsRunningCountsAndEstimates) {
  expect_node_survives_malformed_imu("vehicle");
}

// The selective EKF's second input: kPairs valid VisionPose samples on vision_pose, each followed
// by a malformed one (`dds-test-pub --type vision-malformed`, the same malformed_variants()). The
// node keeps running, exits cleanly on SIGINT, counts the malformed payloads in its status
// ("vision malformed N"; diagnostics counter vision_malformed) and receives the valid poses.
TEST(HostileWire, GivenMalformedVisionPosesWhenASelectiveEkfNodeReadsThemThenItKeepsRunningAndCountsThem) {
  std::string out;
  const std::regex status(R"(vision in (\d+), vision malformed (\d+))");
  const std::smatch m = run_node_against_malformed("selective-ekf", "vision-malformed", kPairs, status, out);
  ASSERT_FALSE(m.empty());
  const int in = std::stoi(m[1]);
  const int malformed = std::stoi(m[2]);
  std::printf("selective-ekf: vision in %d, vision malformed %d of %d + %d published\n", in, malformed,
              kPairs, kPairs);
  // Reliable, loopback: every payload arrives; those fastcdr still accepts (a frame_id without
  // NUL, trailing bytes) count as received (and the EKF, with no IMU yet, does not apply them).
  EXPECT_GE(malformed, 1) << out;
  EXPECT_LE(in + malformed, 2 * kPairs) << out;
  EXPECT_GE(in, kPairs / 4) << "the valid poses must still be received\n" << out;
}

}  // namespace
