// Issue 23: a host's estimator components run live on DDS from a known input order (IMU, vision
// poses, vehicle inputs, each consumed before the next is published), everything is recorded,
// and `poise process` with the same host gives every live estimate back, every field, within
// 1e-9 -- the live node and the processor run the same step logic.
#include "poise/dds/participant.h"
#include "poise/nodes/register.h"
#include "poise/process/compare.h"
#include "poise/record/mcap.h"
#include "poise/process/process.h"
#include "poise/record/recorder.h"
#include "recorder_thread.h"
#include "poise/runtime/host.h"
#include "record_test_support.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cstdlib>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <random>
#include <thread>
#include <tuple>

namespace poise::record {
namespace {

using namespace std::chrono_literals;
constexpr const char* kProfile = "poise_default";  // several participants in one process
constexpr auto kMatchTimeout = 30s;  // discovery on a loaded CI machine
constexpr auto kStepTimeout = 5s;    // one input consumed by every component
constexpr int kSamples = 300;        // 1.5 s at 200 Hz
constexpr int64_t kPeriodNs = 5'000'000;
constexpr int kVisionEvery = 10;     // 20 Hz vision, captured 1 ms after the IMU sample before it
constexpr int kVehicleEvery = 20;    // 10 Hz speed, 2 ms after the IMU sample before it
constexpr int kStartZeroSamples = 200;  // relative_to_start: 1 s at 200 Hz before the first height
constexpr double kYawRateRps = 0.5;
constexpr double kSameValue = 1e-9;  // every field in its SI unit (rad, m, m/s, rad^2, ...)
constexpr uint32_t kSeed = 2323;

constexpr const char* kHost =
    "components:\n"
    "  - {type: parallel_kf, name: pkf}\n"
    "  - {type: selective_ekf, name: sekf, params: {imu_delay_s: 0.002, diagnostics_every: 1}}\n"
    "  - {type: gauss_newton, name: gn}\n"
    "  - {type: altitude, name: alt, params: {relative_to_start: true}}\n"
    "  - {type: vehicle, name: veh}\n";

using Key = std::tuple<std::string, std::string, int64_t, uint32_t>;  // topic, sensor, stamp, seq

/// Every numeric field of the estimates on `topics` (in `prefix` + topic), flattened.
std::map<Key, std::vector<double>> estimates(const std::string& file, const std::string& prefix) {
  std::map<Key, std::vector<double>> out;
  const McapReader reader = McapReader::open_file(file);
  MessageCursor cursor = reader.messages();
  auto v3 = [](std::vector<double>& v, const msg::Vector3& x) { v.insert(v.end(), {x.x(), x.y(), x.z()}); };
  auto q4 = [](std::vector<double>& v, const msg::Quaternion& q) { v.insert(v.end(), {q.w(), q.x(), q.y(), q.z()}); };
  while (const MessageView* m = cursor.next()) {
    const std::string& topic = m->channel->topic;
    if (topic.rfind(prefix, 0) != 0 || m->schema == nullptr) {
      continue;
    }
    const std::string t = topic.substr(prefix.size());
    std::vector<double> v;
    const std::string& type = m->schema->name;
    const std::vector<uint8_t> bytes(m->data, m->data + m->size);
    if (type == "poise::msg::AttitudeEstimate" && t.rfind("attitude/", 0) == 0) {
      const auto e = testing::deserialize<msg::AttitudeEstimatePubSubType>(bytes);
      q4(v, e.q_world_body());
      v.insert(v.end(), {e.roll_rad(), e.pitch_rad(), e.yaw_rad()});
      v.insert(v.end(), e.attitude_covariance().begin(), e.attitude_covariance().end());
      v3(v, e.ext_accel_body_mps2());
      v3(v, e.ext_accel_world_mps2());
      v3(v, e.mag_disturbance_body_ut());
      v3(v, e.mag_disturbance_world_ut());
      v.insert(v.end(), {e.mag_disturbance_norm_ut(), e.mag_disturbance_angle_rad(),
                         e.mag_trusted() ? 1.0 : 0.0, static_cast<double>(e.sources_fused())});
      v3(v, e.gyro_bias_rps());
      out[Key{t, e.sensor_id().to_string(), e.header().stamp_ns(), e.header().seq()}] = v;
    } else if (type == "poise::msg::PoseEstimate" && t.rfind("pose/", 0) == 0) {
      const auto e = testing::deserialize<msg::PoseEstimatePubSubType>(bytes);
      v3(v, e.position_m());
      v3(v, e.velocity_mps());
      q4(v, e.q_world_body());
      v.insert(v.end(), e.covariance().begin(), e.covariance().end());
      v.push_back(static_cast<double>(e.sources_fused()));
      out[Key{t, e.sensor_id().to_string(), e.header().stamp_ns(), e.header().seq()}] = v;
    } else if (type == "poise::msg::AltitudeEstimate" && t == "altitude") {
      const auto e = testing::deserialize<msg::AltitudeEstimatePubSubType>(bytes);
      v.insert(v.end(), {e.height_m(), e.vertical_velocity_mps(), e.vertical_accel_mps2(),
                         e.stationary() ? 1.0 : 0.0, e.baro_valid() ? 1.0 : 0.0, e.baro_height_m(),
                         e.reference_pressure_pa()});
      out[Key{t, e.sensor_id().to_string(), e.header().stamp_ns(), e.header().seq()}] = v;
    }
  }
  return out;
}

/// The number after `what` in the status line of component `name` ("imu in 12"); -1 if absent.
long status_count(const runtime::Host& host, const std::string& name, const std::string& what) {
  for (const std::string& line : host.status()) {
    if (line.rfind(name + ": ", 0) != 0) {
      continue;
    }
    const size_t at = line.find(what + " ");
    return at == std::string::npos ? -1 : std::strtol(line.c_str() + at + what.size() + 1, nullptr, 10);
  }
  return -1;
}

msg::VisionPose vision_pose(uint32_t seq, int64_t stamp_ns, const Eigen::Quaterniond& q,
                            const Eigen::Vector3d& p) {
  msg::VisionPose m;
  m.header().stamp_ns(stamp_ns);
  m.header().seq(seq);
  m.header().frame_id("world");
  m.sensor_id("camera0");
  m.capture_stamp_ns(stamp_ns);
  m.pose_world_camera().position_m(testing::vec3(p.x(), p.y(), p.z()));
  m.pose_world_camera().orientation().w(q.w());
  m.pose_world_camera().orientation().x(q.x());
  m.pose_world_camera().orientation().y(q.y());
  m.pose_world_camera().orientation().z(q.z());
  m.body_valid(false);
  for (int i = 0; i < 6; ++i) {
    m.covariance()[static_cast<size_t>(i * 6 + i)] = i < 3 ? 1e-4 : 3e-4;  // m^2, rad^2
  }
  m.reprojection_rms_px(0.5);
  return m;
}

TEST(ProcessHost, GivenALiveRunFromAKnownInputOrderWhenProcessedThenEveryEstimatorGivesTheLiveEstimates) {
  poise::testing::DomainLease lease;
  const std::string dir = testing::cases_dir("process-host");
  ASSERT_EQ(::setenv("POISE_QOS_FILE", testing::lossless_profiles(dir).c_str(), 1), 0);
  const std::string live_file = dir + "/live.mcap";
  std::printf("seed %u\n", kSeed);
  static const bool registered = [] {
    runtime::register_estimator_nodes(runtime::ComponentRegistry::instance());
    return true;
  }();
  (void)registered;
  runtime::HostSpec spec = runtime::parse_host(YAML::Load(kHost), "test host", dir);
  spec.participant_profile = kProfile;

  // GIVEN every estimator component live, and a recorder of its inputs and outputs
  RecorderOptions ro = testing::recorder_options(live_file, lease.id(), kProfile);
  ro.all = true;
  testing::RecorderThread recorder(ro);
  {
    runtime::Host host(spec, lease.id());
    host.start();
    dds::Participant pub({lease.id(), kProfile, "", "test_inputs"});
    dds::Writer<msg::ImuSamplePubSubType> imu(pub, "imu");
    dds::Writer<msg::VisionPosePubSubType> vision(pub, "vision_pose");
    dds::Writer<msg::VehicleInputPubSubType> vehicle(pub, "vehicle_input");
    // writers: 3 inputs + 4 attitude + 1 pose + 1 altitude + 5 diagnostics
    const bool ready = poise::testing::wait_until(
        [&] {
          return recorder->matched_writers() >= 14 && imu.matched() >= 6 && vision.matched() >= 2 &&
                 vehicle.matched() >= 2;
        },
        kMatchTimeout);
    ASSERT_TRUE(recorder.matched(ready, "components/recorder did not match"));
    // WHEN the inputs are published in stamp order, each consumed by every component before the
    // next goes out: a sensor turning about up at 0.5 rad/s, seen by a camera at the body origin
    std::mt19937 rng(kSeed);
    std::normal_distribution<double> noise(0.0, 0.02);
    const std::vector<std::string> names{"pkf", "sekf", "gn", "alt", "veh"};
    uint32_t vision_seq = 0;
    uint32_t vehicle_seq = 0;
    bool in_order = true;
    for (int i = 0; i < kSamples && in_order; ++i) {
      const int64_t stamp = 1'000'000'000LL + i * kPeriodNs;
      auto m = testing::turning_imu(static_cast<uint32_t>(i), kPeriodNs, kYawRateRps, rng);
      imu.write(m);
      in_order = poise::testing::wait_until(
          [&] {
            for (const auto& n : names) {
              if (status_count(host, n, "imu in") != i + 1) {
                return false;
              }
            }
            return true;
          },
          kStepTimeout);
      if (in_order && i % kVisionEvery == 0) {
        const int64_t capture = stamp + 1'000'000;
        const double yaw_c = kYawRateRps * static_cast<double>(capture - 1'000'000'000LL) * 1e-9;
        vision.write(vision_pose(vision_seq++, capture,
                                 Eigen::Quaterniond(Eigen::AngleAxisd(yaw_c, Eigen::Vector3d::UnitZ())),
                                 Eigen::Vector3d(0.01 * noise(rng), 0.01 * noise(rng), 1.0)));
        in_order = poise::testing::wait_until(
            [&] { return status_count(host, "sekf", "vision in") == static_cast<long>(vision_seq); },
            kStepTimeout);
      }
      if (in_order && i % kVehicleEvery == 0) {
        msg::VehicleInput v;
        v.header().stamp_ns(stamp + 2'000'000);
        v.header().seq(vehicle_seq++);
        v.header().frame_id("body");
        v.sensor_id("car0");
        v.speed_mps(0.0);
        v.speed_valid(true);
        vehicle.write(v);
        in_order = poise::testing::wait_until(
            [&] {
              return status_count(host, "veh", "vehicle_input in") == static_cast<long>(vehicle_seq);
            },
            kStepTimeout);
      }
    }
    // Every input and estimate in the file before the writers go (bounded): a writer that matched
    // the recorder late sends its history then (lossless_profiles); the diagnostics settle after.
    const uint64_t inputs_and_estimates = static_cast<uint64_t>(kSamples) + vision_seq + vehicle_seq +
                                          5U * static_cast<uint64_t>(kSamples) +
                                          static_cast<uint64_t>(kSamples - kStartZeroSamples);
    poise::testing::wait_until([&] { return recorder->written() >= inputs_and_estimates; }, kMatchTimeout);
    testing::wait_quiet([&] { return recorder->written(); });
    const std::vector<std::string> status = host.status();
    host.stop();
    if (!in_order) {
      recorder.stop();
      std::string lines;
      for (const auto& s : status) {
        lines += s + "\n";
      }
      FAIL() << "an input was not consumed within " << kStepTimeout.count() << " s:\n" << lines;
    }
  }
  RecorderStats rstats = recorder.stop();
  ASSERT_TRUE(rstats.error.empty()) << rstats.error;
  ASSERT_EQ(rstats.topics["imu"].written, static_cast<uint64_t>(kSamples)) << recorder.log();
  const auto live = estimates(live_file, "");
  std::map<std::string, size_t> live_per_topic;
  for (const auto& [key, v] : live) {
    ++live_per_topic[std::get<0>(key)];
  }
  // An estimate for every sample (the filters start at the first one); the altitude relative to
  // the start after its 1 s averaging window.
  for (const char* t : {"attitude/parallel_kf", "attitude/selective_ekf", "attitude/gauss_newton",
                        "attitude/vehicle", "pose/selective_ekf"}) {
    EXPECT_EQ(live_per_topic[t], static_cast<size_t>(kSamples)) << t << " was not recorded live";
  }
  EXPECT_EQ(live_per_topic["altitude"], static_cast<size_t>(kSamples - kStartZeroSamples));

  // THEN processing the recording with the same host gives every live estimate, every field
  std::vector<ProcessComponent> components;
  for (const auto& c : spec.components) {
    components.push_back({nodes::make_estimator_step(c), nodes::node_params(c)});
  }
  ProcessOptions po;
  po.input = live_file;
  po.output = dir + "/processed.mcap";
  const ProcessStats stats = process_recording(po, components);
  EXPECT_EQ(stats.vision_samples, static_cast<uint64_t>(kSamples / kVisionEvery));
  EXPECT_EQ(stats.vehicle_inputs, static_cast<uint64_t>(kSamples / kVehicleEvery));
  // (deterministic: the same recording and host give a byte-identical file, vision included)
  {
    std::vector<ProcessComponent> again;
    for (const auto& c : spec.components) {
      again.push_back({nodes::make_estimator_step(c), nodes::node_params(c)});
    }
    ProcessOptions p2 = po;
    p2.output = dir + "/processed_again.mcap";
    process_recording(p2, again);
    auto bytes = [](const std::string& path) {
      std::ifstream in(path, std::ios::binary);
      return std::vector<char>(std::istreambuf_iterator<char>(in), {});
    };
    const auto first = bytes(po.output);
    EXPECT_FALSE(first.empty());
    EXPECT_TRUE(first == bytes(p2.output)) << "two runs gave different files";
  }
  const auto processed = estimates(po.output, "processed/");
  std::map<std::string, double> worst;
  std::map<std::string, size_t> compared;
  for (const auto& [key, lv] : live) {
    const std::string& topic = std::get<0>(key);
    const auto it = processed.find(key);
    if (it == processed.end()) {
      ADD_FAILURE() << topic << " [" << std::get<1>(key) << "] seq " << std::get<3>(key)
                    << ": a live estimate the processor did not produce";
      continue;
    }
    ASSERT_EQ(it->second.size(), lv.size());
    ++compared[topic];
    for (size_t k = 0; k < lv.size(); ++k) {
      worst[topic] = std::max(worst[topic], std::abs(it->second[k] - lv[k]));
    }
  }
  EXPECT_EQ(processed.size(), live.size()) << "the processor produced estimates live did not";
  for (const auto& [topic, n] : live_per_topic) {
    std::printf("%-24s live %zu, compared %zu, largest field difference %.3g\n", topic.c_str(), n,
                compared[topic], worst[topic]);
    EXPECT_EQ(compared[topic], n) << topic;
    EXPECT_LE(worst[topic], kSameValue) << topic;
  }
  // The selective EKF used the vision live and offline (the test is about the vision path too).
  const auto summary = compare_processed(po.output);
  bool sekf_seen = false;
  for (const SeriesComparison& c : summary) {
    if (c.topic == "attitude/selective_ekf") {
      sekf_seen = true;
      EXPECT_EQ(c.matched, c.live);
      EXPECT_EQ(c.vision_fused.processed_only + c.vision_fused.live_only, 0U);
    }
  }
  EXPECT_TRUE(sekf_seen) << format_comparison(summary);
  // The diagnostics of the selective EKF are there offline with every part filled: its sources
  // with decisions, the core's counters (vision ones included), the node's counters and metrics.
  {
    const McapReader reader = McapReader::open_file(po.output);
    ReadFilter f;
    f.topics = {"processed/diagnostics"};
    MessageCursor cursor = reader.messages(f);
    msg::FilterDiagnostics last;
    uint64_t sekf_diagnostics = 0;
    while (const MessageView* m = cursor.next()) {
      auto d = testing::deserialize<msg::FilterDiagnosticsPubSubType>(
          std::vector<uint8_t>(m->data, m->data + m->size));
      if (d.sensor_id().to_string() == "sekf") {
        ++sekf_diagnostics;
        last = d;
      }
    }
    EXPECT_EQ(sekf_diagnostics, static_cast<uint64_t>(kSamples));  // diagnostics_every 1
    EXPECT_EQ(last.header().seq(), static_cast<uint32_t>(kSamples - 1));
    EXPECT_EQ(last.component_name().to_string(), "selective_ekf");
    std::map<std::string, uint64_t> counters;
    for (const auto& c : last.counters()) {
      counters[c.name().to_string()] = c.value();
    }
    EXPECT_EQ(counters["samples_received"], static_cast<uint64_t>(kSamples));
    EXPECT_EQ(counters["vision_received"], static_cast<uint64_t>(kSamples / kVisionEvery));
    EXPECT_EQ(counters["imu_received"], static_cast<uint64_t>(kSamples));
    EXPECT_EQ(counters["imu_lost"], 0U);
    std::set<std::string> sources;
    for (const auto& src : last.sources()) {
      sources.insert(src.source().to_string());
    }
    EXPECT_EQ(sources.count("vision_attitude"), 1U);
    EXPECT_EQ(sources.count("mag"), 1U);
    EXPECT_FALSE(last.metrics().empty());
  }
  uint64_t vision_fused = 0;  // field 31: sources_fused
  for (const auto& [key, v] : processed) {
    if (std::get<0>(key) == "attitude/selective_ekf") {
      vision_fused += (static_cast<uint32_t>(v[31]) & msg::SOURCE_VISION) != 0 ? 1 : 0;
    }
  }
  EXPECT_GT(vision_fused, 0U) << "the selective EKF never fused a vision pose";
}

}  // namespace
}  // namespace poise::record
