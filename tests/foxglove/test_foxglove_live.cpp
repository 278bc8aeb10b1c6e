// The foxglove_bridge component live on DDS, checked by an independent client: the npm package
// @foxglove/ws-protocol (FoxgloveClient over `ws`) decoding the advertised omgidl schemas with
// @foxglove/omgidl-serialization, as Foxglove does (client/client.mjs, installed into the build
// tree at test time). Under CI=true a missing node/npm or registry is a failure, not a skip.
#include "poise/dds/convert.h"
#include "poise/dds/participant.h"
#include "poise/schema/idl_schema.h"
#include "poise/foxglove/bridge.h"
#include "poise/nodes/register.h"
#include "poise/runtime/host.h"
#include "poise/testing/npm.h"
#include "poise/testing/testing.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <arpa/inet.h>
#include <signal.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

namespace poise::foxglove {
namespace {

using namespace std::chrono_literals;
using nlohmann::json;

// Several participants in one process on a leased domain: multicast discovery (as record_live).
constexpr const char* kProfile = "poise_default";
constexpr auto kMatchTimeout = 30s;   // discovery on a loaded CI machine
constexpr double kYawRateRps = 0.5;
constexpr double kSameValue = 0.0;    // forwarded bytes decoded independently: bit-identical
constexpr double kNormalised = 1e-12; // a normalised unit quaternion vs the original, dimensionless
constexpr double kDegTolerance = 1e-9;  // rad -> deg in the plot message, deg

std::string client_dir() { return POISE_FOXGLOVE_CLIENT_DIR; }

std::string require_client() {
  return poise::testing::npm_install(client_dir(), {"@foxglove/ws-protocol", "@foxglove/omgidl-parser",
                                                    "@foxglove/omgidl-serialization", "ws"});
}

/// Installs the client's npm packages, or skips the test (fails it under CI=true) with why not.
#define POISE_REQUIRE_FOXGLOVE_CLIENT()          \
  do {                                           \
    const std::string missing = require_client(); \
    if (!missing.empty()) {                      \
      POISE_SKIP(missing);                       \
    }                                            \
  } while (false)

std::int64_t realtime_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

/// A free TCP port on 127.0.0.1 (bound then released).
int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof a;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
    ::close(fd);
    return 0;
  }
  ::close(fd);
  return ntohs(a.sin_port);
}

msg::Vector3 vec(double x, double y, double z) { return dds::to_msg(Eigen::Vector3d(x, y, z)); }

/// Sample I of a level sensor turning about up at kYawRateRps (consistent magnetometer), with
/// small distinct values in every field.
msg::ImuSample imu_sample(std::uint32_t i, std::int64_t period_ns) {
  const double t = static_cast<double>(i) * static_cast<double>(period_ns) * 1e-9;
  const double yaw = kYawRateRps * t;
  msg::ImuSample m;
  m.header().stamp_ns(1'000'000'000 + static_cast<std::int64_t>(i) * period_ns);
  m.header().seq(i);
  m.header().frame_id("body");
  m.sensor_id("imu0");
  m.accel_mps2(vec(0.001 * std::sin(i), -0.001 * std::cos(i), 9.81));
  m.gyro_rps(vec(0.0001 * (i % 7), 0.0, kYawRateRps));
  m.mag_ut(vec(20.0 * std::sin(yaw), 20.0 * std::cos(yaw), -40.0));
  m.pressure_pa(101325.0 + 0.01 * i);
  m.temperature_c(21.5);
  m.valid().accel(true);
  m.valid().gyro(true);
  m.valid().mag(true);
  m.valid().pressure(true);
  m.valid().temperature(true);
  return m;
}

struct Live {
  poise::testing::DomainLease lease;
  int port = free_port();
  std::unique_ptr<runtime::Host> host;

  explicit Live(const YAML::Node& bridge_params, bool with_filter = true) {
    static const bool registered = [] {
      auto& r = runtime::ComponentRegistry::instance();
      runtime::register_estimator_nodes(r);
      register_foxglove_bridge(r);
      return true;
    }();
    (void)registered;
    runtime::HostSpec spec;
    spec.participant_profile = kProfile;
    if (with_filter) {
      runtime::ComponentSpec f;
      f.type = "parallel_kf";
      f.name = "parallel_kf";
      f.origin = "test";
      f.params = YAML::Node(YAML::NodeType::Map);
      spec.components.push_back(f);
    }
    runtime::ComponentSpec b;
    b.type = "foxglove_bridge";
    b.name = "foxglove";
    b.origin = "test";
    b.params = YAML::Clone(bridge_params);
    b.params["port"] = port;
    b.params["address"] = "127.0.0.1";
    spec.components.push_back(b);
    host = std::make_unique<runtime::Host>(spec, lease.id());
    host->start();
  }
  [[nodiscard]] std::string url() const { return "ws://127.0.0.1:" + std::to_string(port); }
  [[nodiscard]] std::string bridge_status() const { return host->status().back(); }
};

dds::ParticipantOptions test_participant(int domain) {
  dds::ParticipantOptions o;
  o.domain = domain;
  o.profile = kProfile;
  o.name = "foxglove-test";
  return o;
}

std::vector<json> read_lines(const std::string& path) {
  std::vector<json> out;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty()) {
      out.push_back(json::parse(line));
    }
  }
  return out;
}

std::int64_t to_i64(const json& j) { return j.is_string() ? std::stoll(j.get<std::string>()) : j.get<std::int64_t>(); }

std::string temp_dir(const std::string& name) {
  const std::string dir = client_dir() + "/run-" + name + "-" + std::to_string(::getpid());
  const std::string cmd = "rm -rf '" + dir + "' && mkdir -p '" + dir + "'";
  return std::system(cmd.c_str()) == 0 ? dir : "";
}

bool wait_file(const std::string& path, std::chrono::milliseconds timeout) {
  return poise::testing::wait_until([&] { return std::ifstream(path).good(); }, timeout);
}

// GIVEN a host with the parallel KF and the bridge, and an IMU publisher
// WHEN the independent client subscribes to imu, attitude/parallel_kf and the panel channels
// THEN every message it decodes with the advertised schema equals, field for field, the sample a
//      DDS reader of the same test got with the same seq; the transforms and plots carry the
//      estimates' quaternions, angles and stamps.
TEST(FoxgloveBridge, GivenLiveTopicsWhenTheWsProtocolClientDecodesThemThenTheyEqualWhatDdsDelivers) {
  POISE_REQUIRE_FOXGLOVE_CLIENT();
  constexpr int kSamples = 200;
  constexpr std::int64_t kPeriodNs = 5'000'000;  // 200 Hz
  YAML::Node params(YAML::NodeType::Map);
  params["stamps"] = "sensor";  // panel stamps = stamp_ns: comparable with the DDS samples
  Live live(params);
  dds::Participant participant(test_participant(live.lease.id()));
  std::mutex mutex;
  std::map<std::uint32_t, msg::ImuSample> dds_imu;
  std::map<std::uint32_t, msg::AttitudeEstimate> dds_att;
  dds::Reader<msg::ImuSamplePubSubType> imu_reader(participant, "imu", [&](const msg::ImuSample& m, const auto&) {
    std::lock_guard<std::mutex> lock(mutex);
    dds_imu[m.header().seq()] = m;
  });
  dds::Reader<msg::AttitudeEstimatePubSubType> att_reader(
      participant, "attitude/parallel_kf", [&](const msg::AttitudeEstimate& m, const auto&) {
        std::lock_guard<std::mutex> lock(mutex);
        dds_att[m.header().seq()] = m;
      });
  dds::Writer<msg::ImuSamplePubSubType> writer(participant, "imu");
  // The filter, this test's reader and the bridge's raw reader.
  ASSERT_TRUE(writer.wait_for_readers(3, kMatchTimeout)) << "matched " << writer.matched();

  const std::string dir = temp_dir("decode");
  const std::string out = dir + "/out.jsonl";
  const std::string ready = dir + "/ready";
  poise::testing::Child client({poise::testing::find_on_path("node"), client_dir() + "/client.mjs", "decode",
                                live.url(), out, ready, std::to_string(kSamples * 9 / 10), "60", "imu",
                                "attitude/parallel_kf", "foxglove/tf", "foxglove/attitude/parallel_kf"});
  ASSERT_TRUE(wait_file(ready, 30s)) << client.output();
  std::this_thread::sleep_for(1s);  // the bridge's reader of attitude/parallel_kf matches
  const std::int64_t t0 = realtime_ns();
  auto next = std::chrono::steady_clock::now();
  for (int i = 0; i < kSamples; ++i) {
    writer.write(imu_sample(static_cast<std::uint32_t>(i), kPeriodNs));
    next += std::chrono::nanoseconds(kPeriodNs);
    std::this_thread::sleep_until(next);
  }
  const auto code = client.wait_for(60s);
  const std::int64_t t1 = realtime_ns();
  ASSERT_TRUE(code.has_value() && *code == 0) << client.output();

  const std::vector<json> lines = read_lines(out);
  ASSERT_FALSE(lines.empty());
  const json& header = lines.front();
  EXPECT_EQ(header["serverInfo"]["op"], "serverInfo");
  const auto& table = schema::TypeTable::builtin();
  std::map<std::string, json> channels;
  for (const auto& c : header["channels"]) {
    channels[c["topic"].get<std::string>()] = c;
  }
  ASSERT_EQ(channels.count("imu"), 1u);
  EXPECT_EQ(channels["imu"]["encoding"], "cdr");
  EXPECT_EQ(channels["imu"]["schemaEncoding"], "omgidl");
  EXPECT_EQ(channels["imu"]["schemaName"], "poise::msg::ImuSample");
  EXPECT_EQ(channels["imu"]["schema"], table.flatten("poise::msg::ImuSample"));  // what MCAP holds
  EXPECT_EQ(channels["attitude/parallel_kf"]["schemaName"], "poise::msg::AttitudeEstimate");
  EXPECT_EQ(channels["foxglove/tf"]["schemaName"], "foxglove.FrameTransform");
  EXPECT_EQ(channels["foxglove/tf"]["encoding"], "json");
  EXPECT_EQ(channels["foxglove/tf"]["schemaEncoding"], "jsonschema");

  std::lock_guard<std::mutex> lock(mutex);
  std::map<std::int64_t, const msg::AttitudeEstimate*> att_by_stamp;
  for (const auto& [seq, m] : dds_att) {
    att_by_stamp[m.header().stamp_ns()] = &m;
  }
  std::map<std::string, int> compared;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const json& l = lines[i];
    const std::string topic = l["topic"];
    const json& m = l["message"];
    const std::int64_t receive = to_i64(l["receive_ns"]);
    EXPECT_GE(receive, t0 - 2'000'000'000) << "receive time on CLOCK_REALTIME";
    EXPECT_LE(receive, t1);
    if (topic == "imu") {
      const auto seq = m["header"]["seq"].get<std::uint32_t>();
      const auto it = dds_imu.find(seq);
      if (it == dds_imu.end()) {
        continue;  // best effort: this test's reader lost it
      }
      const msg::ImuSample& d = it->second;
      EXPECT_EQ(to_i64(m["header"]["stamp_ns"]), d.header().stamp_ns());
      EXPECT_EQ(m["header"]["frame_id"], d.header().frame_id());
      EXPECT_EQ(m["sensor_id"], d.sensor_id());
      EXPECT_NEAR(m["accel_mps2"]["x"].get<double>(), d.accel_mps2().x(), kSameValue);
      EXPECT_NEAR(m["accel_mps2"]["y"].get<double>(), d.accel_mps2().y(), kSameValue);
      EXPECT_NEAR(m["gyro_rps"]["x"].get<double>(), d.gyro_rps().x(), kSameValue);
      EXPECT_NEAR(m["mag_ut"]["x"].get<double>(), d.mag_ut().x(), kSameValue);
      EXPECT_NEAR(m["mag_ut"]["y"].get<double>(), d.mag_ut().y(), kSameValue);
      EXPECT_NEAR(m["pressure_pa"].get<double>(), d.pressure_pa(), kSameValue);
      EXPECT_EQ(m["valid"]["mag"].get<bool>(), d.valid().mag());
      ++compared[topic];
    } else if (topic == "attitude/parallel_kf") {
      const auto it = dds_att.find(m["header"]["seq"].get<std::uint32_t>());
      if (it == dds_att.end()) {
        continue;
      }
      const msg::AttitudeEstimate& d = it->second;
      EXPECT_EQ(to_i64(m["header"]["stamp_ns"]), d.header().stamp_ns());
      EXPECT_EQ(m["filter_id"], d.filter_id());
      EXPECT_NEAR(m["q_world_body"]["w"].get<double>(), d.q_world_body().w(), kSameValue);
      EXPECT_NEAR(m["q_world_body"]["x"].get<double>(), d.q_world_body().x(), kSameValue);
      EXPECT_NEAR(m["q_world_body"]["z"].get<double>(), d.q_world_body().z(), kSameValue);
      EXPECT_NEAR(m["yaw_rad"].get<double>(), d.yaw_rad(), kSameValue);
      EXPECT_NEAR(m["mag_disturbance_norm_ut"].get<double>(), d.mag_disturbance_norm_ut(), kSameValue);
      EXPECT_EQ(m["mag_trusted"].get<bool>(), d.mag_trusted());
      EXPECT_NEAR(m["attitude_covariance"][4].get<double>(), d.attitude_covariance()[4], kSameValue);
      ++compared[topic];
    } else if (topic == "foxglove/tf" || topic == "foxglove/attitude/parallel_kf") {
      const std::int64_t stamp = m["timestamp"]["sec"].get<std::int64_t>() * 1'000'000'000 +
                                 m["timestamp"]["nsec"].get<std::int64_t>();
      const auto it = att_by_stamp.find(stamp);
      if (it == att_by_stamp.end()) {
        continue;
      }
      const msg::AttitudeEstimate& d = *it->second;
      if (topic == "foxglove/tf") {
        EXPECT_EQ(m["parent_frame_id"], "world");
        EXPECT_EQ(m["child_frame_id"], "parallel_kf");
        EXPECT_NEAR(m["rotation"]["w"].get<double>(), d.q_world_body().w(), kNormalised);
        EXPECT_NEAR(m["rotation"]["x"].get<double>(), d.q_world_body().x(), kNormalised);
        EXPECT_NEAR(m["rotation"]["y"].get<double>(), d.q_world_body().y(), kNormalised);
        EXPECT_NEAR(m["rotation"]["z"].get<double>(), d.q_world_body().z(), kNormalised);
        EXPECT_EQ(m["translation"]["x"].get<double>(), 0.6);  // slot 1 x the default spacing
      } else {
        EXPECT_NEAR(m["rpy_deg"]["z"].get<double>(), d.yaw_rad() * 180.0 / M_PI, kDegTolerance);
        EXPECT_NEAR(m["mag_disturbance_norm_ut"].get<double>(), d.mag_disturbance_norm_ut(), kSameValue);
        EXPECT_EQ(m["mag_trusted"].get<int>(), d.mag_trusted() ? 1 : 0);
      }
      ++compared[topic];
    }
  }
  std::printf("compared: imu %d, attitude %d, tf %d, plot %d (published %d)\n", compared["imu"],
              compared["attitude/parallel_kf"], compared["foxglove/tf"], compared["foxglove/attitude/parallel_kf"],
              kSamples);
  // Loopback, 200 Hz: at most a few samples lost on the best-effort paths.
  EXPECT_GE(compared["imu"], kSamples * 8 / 10);
  EXPECT_GE(compared["attitude/parallel_kf"], kSamples * 8 / 10);
  EXPECT_GE(compared["foxglove/tf"], kSamples * 8 / 10);
  EXPECT_GE(compared["foxglove/attitude/parallel_kf"], kSamples * 8 / 10);
}

// GIVEN a running bridge with a live topic
// WHEN a raw client sends every kind of malformed frame (bad JSON, not an object, no op, unknown
//      and unsupported ops, malformed subscriptions, unknown channel, reused id, deep nesting, an
//      oversized request, a binary frame), then a frame beyond the hard limit, and a client
//      connects without the subprotocol
// THEN each malformed frame gets an error status (level 2) on a connection that stays open, the
//      giant frame closes its connection (1009, or a reset while the client still writes), the handshake without subprotocol is refused
//      (HTTP 400), and a good client is still served afterwards.
TEST(FoxgloveBridge, GivenMalformedClientFramesThenErrorStatusesNeverACrashAndGoodClientsAreServed) {
  POISE_REQUIRE_FOXGLOVE_CLIENT();
  Live live(YAML::Node(YAML::NodeType::Map), false);
  dds::Participant participant(test_participant(live.lease.id()));
  dds::Writer<msg::ImuSamplePubSubType> writer(participant, "imu");
  ASSERT_TRUE(writer.wait_for_readers(1, kMatchTimeout));
  std::atomic<bool> stop{false};
  std::thread publisher([&] {
    for (std::uint32_t i = 0; !stop.load(); ++i) {
      writer.write(imu_sample(i, 10'000'000));
      std::this_thread::sleep_for(10ms);
    }
  });
  std::this_thread::sleep_for(500ms);  // the bridge advertises imu
  const std::string dir = temp_dir("malformed");
  const auto r = poise::testing::run({poise::testing::find_on_path("node"), client_dir() + "/client.mjs", "malformed",
                                      live.url(), dir + "/out.json"},
                                     90s);
  stop.store(true);
  publisher.join();
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto lines = read_lines(dir + "/out.json");
  ASSERT_EQ(lines.size(), 1u);
  const json& result = lines[0];
  ASSERT_GE(result["cases"].size(), 16u) << "the duplicate-id case needs an advertised channel";
  for (const auto& c : result["cases"]) {
    bool error = false;
    for (const auto& s : c["statuses"]) {
      error = error || s["level"] == 2;
    }
    EXPECT_TRUE(error) << c["name"] << ": " << c["statuses"].dump();
  }
  EXPECT_TRUE(result["raw_still_open"].get<bool>());
  // websocketpp closes with 1009 (message too big) as soon as it reads the frame header; the
  // client, still writing its 8 MiB, sees either that close frame or the reset (1006).
  EXPECT_TRUE(result["huge"] == 1009 || result["huge"] == 1006) << result["huge"];
  EXPECT_EQ(result["no_subprotocol"]["refused"], 400);
  EXPECT_EQ(result["good"]["serverInfo"]["op"], "serverInfo");
  EXPECT_GE(result["good"]["channels"].get<int>(), 1);
  EXPECT_GT(result["good"]["messages"].get<int>(), 0);
  const std::string status = live.bridge_status();
  EXPECT_NE(status.find("requests refused"), std::string::npos) << status;
  std::printf("bridge: %s\n", status.c_str());
}

long rss_kib() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) {
      return std::stol(line.substr(6));
    }
  }
  return -1;
}

// GIVEN the parallel KF at 500 Hz and the bridge with two clients subscribed to everything, one
//      of which stops reading (its socket paused) for 60 s
// WHEN the IMU keeps publishing
// THEN the estimator keeps its rate, the good client keeps the IMU rate, the stalled client's
//      dropped frames are counted (diagnostics and status line), and the process's memory stays
//      bounded.
TEST(FoxgloveBridge, GivenAStalledClientThenTheEstimatorAndTheOtherClientKeepTheirRateAndMemoryIsBounded) {
  POISE_REQUIRE_FOXGLOVE_CLIENT();
  constexpr int kSeconds = 60;
  constexpr std::int64_t kPeriodNs = 2'000'000;  // 500 Hz
  constexpr double kRateHz = 500.0;
  constexpr double kKeptRate = 0.9;              // of the published rate, over the window
  constexpr long kMaxGrowthKib = 32 * 1024;      // RSS growth after the first 15 s, KiB
  YAML::Node params(YAML::NodeType::Map);
  params["queue_frames"] = 500;
  params["socket_buffer_bytes"] = 262144;
  params["diagnostics_period_s"] = 0.5;
  Live live(params);
  dds::Participant participant(test_participant(live.lease.id()));
  std::atomic<std::uint64_t> estimates{0};
  std::atomic<std::uint64_t> reported_drops{0};
  dds::Reader<msg::AttitudeEstimatePubSubType> att_reader(
      participant, "attitude/parallel_kf", [&](const msg::AttitudeEstimate&, const auto&) { estimates.fetch_add(1); });
  dds::Reader<msg::FilterDiagnosticsPubSubType> diag_reader(
      participant, "diagnostics", [&](const msg::FilterDiagnostics& d, const auto&) {
        if (d.component_name() != "foxglove_bridge") {
          return;
        }
        std::uint64_t dropped = 0;
        for (const auto& c : d.counters()) {
          const std::string name = c.name().to_string();
          if (name.rfind("client_", 0) == 0 && name.find("_dropped") != std::string::npos) {
            dropped += c.value();
          }
        }
        reported_drops.store(std::max(reported_drops.load(), dropped));
      });
  dds::Writer<msg::ImuSamplePubSubType> writer(participant, "imu");
  ASSERT_TRUE(writer.wait_for_readers(2, kMatchTimeout));
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> published{0};
  std::thread publisher([&] {
    auto next = std::chrono::steady_clock::now();
    for (std::uint32_t i = 0; !stop.load(); ++i) {
      writer.write(imu_sample(i, kPeriodNs));
      published.fetch_add(1);
      next += std::chrono::nanoseconds(kPeriodNs);
      std::this_thread::sleep_until(next);
    }
  });
  std::this_thread::sleep_for(1s);  // every channel advertised before the clients connect
  const std::string dir = temp_dir("stall");
  poise::testing::Child client({poise::testing::find_on_path("node"), client_dir() + "/client.mjs", "stall",
                                live.url(), dir + "/out.json", std::to_string(kSeconds), dir + "/ready"});
  ASSERT_TRUE(wait_file(dir + "/ready", 30s)) << client.output();
  const auto start = std::chrono::steady_clock::now();
  const std::uint64_t published0 = published.load();
  const std::uint64_t estimates0 = estimates.load();
  long rss15 = 0;
  long rss_max = 0;
  while (std::chrono::steady_clock::now() - start < std::chrono::seconds(kSeconds - 2)) {
    std::this_thread::sleep_for(1s);
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (t >= 15.0 && rss15 == 0) {
      rss15 = rss_kib();
    }
    rss_max = std::max(rss_max, rss_kib());
  }
  const std::uint64_t published_n = published.load() - published0;
  const std::uint64_t estimates_n = estimates.load() - estimates0;
  const std::string status = live.bridge_status();
  const auto code = client.wait_for(30s);
  stop.store(true);
  publisher.join();
  ASSERT_TRUE(code.has_value() && *code == 0) << client.output();
  const auto lines = read_lines(dir + "/out.json");
  ASSERT_EQ(lines.size(), 1u);
  const json& imu = lines[0]["per_second"]["imu"];
  // Seconds 5 .. kSeconds - 5 of the good client (its connection and subscription settle first).
  double good = 0.0;
  int seconds = 0;
  for (int s = 5; s < kSeconds - 5 && s < static_cast<int>(imu.size()); ++s, ++seconds) {
    good += imu[s].is_number() ? imu[s].get<double>() : 0.0;
  }
  const double good_rate = seconds > 0 ? good / seconds : 0.0;
  const double published_rate = static_cast<double>(published_n) / (kSeconds - 2);
  std::printf("published %.1f Hz, estimates %llu of %llu, good client imu %.1f Hz, stalled client's drops "
              "(diagnostics) %llu, RSS %ld KiB at 15 s, max %ld KiB\nbridge: %s\n",
              published_rate, static_cast<unsigned long long>(estimates_n),
              static_cast<unsigned long long>(published_n), good_rate,
              static_cast<unsigned long long>(reported_drops.load()), rss15, rss_max, status.c_str());
  EXPECT_GE(published_rate, kKeptRate * kRateHz) << "the publisher itself fell behind";
  EXPECT_GE(static_cast<double>(estimates_n), kKeptRate * static_cast<double>(published_n));
  EXPECT_GE(good_rate, kKeptRate * published_rate);
  EXPECT_GT(reported_drops.load(), 0u) << "the stalled client's drops are reported in diagnostics";
  EXPECT_NE(status.find("(client 1 "), std::string::npos) << "the status line names the stalled client";
  EXPECT_GT(lines[0]["stalled_channels"].get<int>(), 3);
  EXPECT_LT(rss_max - rss15, kMaxGrowthKib);
}

// GIVEN a bridge serving a topic
// WHEN the topic's only writer goes away for longer than unadvertise_after_s, then comes back
// THEN the client is told the channel is gone (unadvertise), then it is advertised again under the
//      same id with the same topic, encoding and schema.
TEST(FoxgloveBridge, GivenATopicWhoseWritersLeaveAndReturnThenItIsUnadvertisedAndAdvertisedAgainWithItsId) {
  POISE_REQUIRE_FOXGLOVE_CLIENT();
  YAML::Node params(YAML::NodeType::Map);
  params["unadvertise_after_s"] = 0.5;
  Live live(params, false);
  dds::Participant participant(test_participant(live.lease.id()));
  auto writer = std::make_unique<dds::Writer<msg::ImuSamplePubSubType>>(participant, "imu");
  ASSERT_TRUE(writer->wait_for_readers(1, kMatchTimeout));
  const std::string dir = temp_dir("unadvertise");
  poise::testing::Child client({poise::testing::find_on_path("node"), client_dir() + "/client.mjs", "decode",
                                live.url(), dir + "/out.jsonl", dir + "/ready", "1000000", "8", "imu"});
  ASSERT_TRUE(wait_file(dir + "/ready", 30s)) << client.output();
  writer.reset();  // the only writer of imu leaves
  std::this_thread::sleep_for(2500ms);
  writer = std::make_unique<dds::Writer<msg::ImuSamplePubSubType>>(participant, "imu");
  const auto code = client.wait_for(30s);
  ASSERT_TRUE(code.has_value() && *code == 0) << client.output();
  const auto lines = read_lines(dir + "/out.jsonl");
  ASSERT_FALSE(lines.empty());
  std::vector<json> imu;
  for (const auto& c : lines[0]["channels"]) {
    if (c["topic"] == "imu") {
      imu.push_back(c);
    }
  }
  ASSERT_EQ(imu.size(), 2u) << lines[0].dump();
  EXPECT_EQ(imu[0], imu[1]) << "the same id, encoding and schema";
  ASSERT_EQ(lines[0]["unadvertised"].size(), 1u) << lines[0].dump();
  EXPECT_EQ(lines[0]["unadvertised"][0], imu[0]["id"]);
}

/// True when /proc/net/tcp holds a listening socket (state 0A) on `address_hex:port`
/// (`address_hex` as the kernel prints an IPv4 address: 127.0.0.1 is 0100007F, 0.0.0.0 00000000).
bool listening(const std::string& address_hex, int port) {
  std::ifstream in("/proc/net/tcp");
  char local[32];
  std::snprintf(local, sizeof local, "%s:%04X", address_hex.c_str(), port);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string slot;
    std::string l;
    std::string remote;
    std::string state;
    fields >> slot >> l >> remote >> state;
    if (l == local && state == "0A") {
      return true;
    }
  }
  return false;
}

// GIVEN `poise foxglove` with the port and address options every Foxglove bridge takes
// WHEN it starts
// THEN it listens on exactly that address and port (the kernel's socket table, read independently);
//      `--set port=N` still works (every interface by default); the same parameter given both ways
//      is a usage error naming both (exit 2); a port out of range a startup error naming it (exit 1).
TEST(FoxgloveCli, GivenPortAndAddressOptionsThenItListensThereSetStillWorksAndBothWaysAreRefused) {
  poise::testing::DomainLease lease;
  const std::string domain = std::to_string(lease.id());
  const std::string poise = poise::testing::bin("poise");
  const int port = free_port();
  ASSERT_GT(port, 0);
  {
    poise::testing::Child bridge({poise, "foxglove", "--port", std::to_string(port), "--address", "127.0.0.1",
                                  "--domain", domain, "--duration", "30"});
    EXPECT_TRUE(poise::testing::wait_until([&] { return listening("0100007F", port); }, 20s)) << bridge.output();
    EXPECT_FALSE(listening("00000000", port)) << "--address 127.0.0.1 must not listen on every interface";
    bridge.signal(SIGINT);
    const auto code = bridge.wait_for(20s);
    EXPECT_TRUE(code.has_value() && *code == 0) << bridge.output();
  }
  const int other = free_port();
  {
    poise::testing::Child bridge({poise, "foxglove", "--set", "port=" + std::to_string(other), "--domain", domain,
                                  "--duration", "30"});
    EXPECT_TRUE(poise::testing::wait_until([&] { return listening("00000000", other); }, 20s)) << bridge.output();
    bridge.signal(SIGINT);
    const auto code = bridge.wait_for(20s);
    EXPECT_TRUE(code.has_value() && *code == 0) << bridge.output();
  }
  const auto both = poise::testing::run({poise, "foxglove", "--port", std::to_string(port), "--set",
                                         "port=" + std::to_string(other), "--domain", domain, "--duration", "1"},
                                        30s);
  EXPECT_EQ(both.exit_code, 2) << both.output;
  EXPECT_NE(both.output.find("--port and --set port=" + std::to_string(other) + " both set 'port'"), std::string::npos)
      << both.output;
  const auto bad = poise::testing::run({poise, "foxglove", "--port", "70000", "--domain", domain, "--duration", "1"}, 30s);
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("parameter 'port'"), std::string::npos) << bad.output;
}

// GIVEN `poise demo --foxglove PORT`
// WHEN it runs
// THEN it prints the URL to open and serves the demo's estimates to a client on that port; a port
//      that is not one is a usage error (exit 2).
TEST(FoxgloveDemo, GivenTheFoxgloveFlagThenTheDemoPrintsTheUrlAndServesItsEstimates) {
  POISE_REQUIRE_FOXGLOVE_CLIENT();
  poise::testing::DomainLease lease;
  const int port = free_port();
  const std::string dir = temp_dir("demo");
  poise::testing::Child demo({poise::testing::bin("poise"), "demo", "--foxglove", std::to_string(port), "--duration",
                              "10", "--plain", "--domain", std::to_string(lease.id()), "--out-dir", dir + "/report"});
  const std::string url_line = "Foxglove: open ws://";
  ASSERT_TRUE(poise::testing::wait_until(
      [&] {
        const std::string out = demo.output();
        return out.find(url_line) != std::string::npos && out.find(":" + std::to_string(port) + " ") != std::string::npos;
      },
      30s))
      << demo.output();
  const auto r = poise::testing::run({poise::testing::find_on_path("node"), client_dir() + "/client.mjs", "decode",
                                      "ws://127.0.0.1:" + std::to_string(port), dir + "/out.jsonl", dir + "/ready", "20",
                                      "15", "attitude/parallel_kf"},
                                     60s);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto lines = read_lines(dir + "/out.jsonl");
  ASSERT_GE(lines.size(), 2u) << "no attitude/parallel_kf message from the demo";
  EXPECT_EQ(lines[1]["topic"], "attitude/parallel_kf");
  EXPECT_EQ(lines[1]["message"]["filter_id"], "parallel_kf");
  const auto code = demo.wait_for(60s);
  EXPECT_TRUE(code.has_value() && *code == 0) << demo.output();
  const auto bad = poise::testing::run({poise::testing::bin("poise"), "demo", "--foxglove", "70000", "--duration", "1"}, 30s);
  EXPECT_EQ(bad.exit_code, 2) << bad.output;
}

}  // namespace
}  // namespace poise::foxglove
