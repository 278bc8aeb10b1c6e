// Helpers for the recorder tests: poise messages with known values, their CDR bytes, the expected
// values as JSON for the independent node validator (validator/validate.mjs), and running it.
#pragma once

#include "poise/testing/npm.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include <fastdds/rtps/common/SerializedPayload.h>

#include <chrono>
#include <cmath>
#include <random>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

namespace poise::record::testing {

inline msg::Vector3 vec3(double x, double y, double z) {
  msg::Vector3 v;
  v.x(x);
  v.y(y);
  v.z(z);
  return v;
}

/// An IMU sample whose every field derives from I (distinct, exactly representable values).
inline msg::ImuSample make_imu(uint32_t i, int64_t stamp_ns) {
  msg::ImuSample m;
  m.header().stamp_ns(stamp_ns);
  m.header().seq(i);
  m.header().frame_id("body");
  m.sensor_id("imu0");
  m.accel_mps2(vec3(0.125 * i, -0.25 * i, 9.8125));
  m.gyro_rps(vec3(0.001953125 * i, -0.5, 0.75));
  m.mag_ut(vec3(20.5, -3.25 * i, 40.0));
  m.pressure_pa(101325.0 + i);
  m.temperature_c(21.5);
  m.valid().accel(true);
  m.valid().gyro(true);
  m.valid().mag(i % 2 == 0);
  m.valid().pressure(true);
  m.valid().temperature(false);
  return m;
}

/// Sample I (stamp 1 s + I * PERIOD_NS) of a level sensor turning about up at YAW_RATE_RPS, with
/// a consistent magnetometer (world field [0, 20, -40] uT), pressure, and seeded noise (0.02 in
/// each unit; gyro 0.002 rad/s) drawn from RNG: a skipped, repeated or reordered sample changes
/// what a filter estimates.
inline msg::ImuSample turning_imu(uint32_t i, int64_t period_ns, double yaw_rate_rps, std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, 0.02);
  const double yaw = yaw_rate_rps * static_cast<double>(static_cast<int64_t>(i) * period_ns) * 1e-9;
  // magnetometer in the body frame: the world field rotated by -yaw about up
  const double mx = 20.0 * std::sin(yaw);
  const double my = 20.0 * std::cos(yaw);
  msg::ImuSample m = make_imu(i, 1'000'000'000LL + static_cast<int64_t>(i) * period_ns);
  m.accel_mps2(vec3(noise(rng), noise(rng), 9.81 + noise(rng)));
  m.gyro_rps(vec3(noise(rng) * 0.1, noise(rng) * 0.1, yaw_rate_rps + noise(rng) * 0.1));
  m.mag_ut(vec3(mx + noise(rng), my + noise(rng), -40.0 + noise(rng)));
  m.pressure_pa(101325.0 + 10.0 * noise(rng));
  m.valid().mag(true);
  m.valid().pressure(true);
  return m;
}

inline msg::AttitudeEstimate make_attitude(uint32_t i, int64_t stamp_ns) {
  msg::AttitudeEstimate m;
  m.header().stamp_ns(stamp_ns);
  m.header().seq(i);
  m.header().frame_id("world");
  m.sensor_id("imu0");
  m.filter_id("parallel_kf");
  m.q_world_body().w(1.0);
  m.q_world_body().x(0.0625 * i);
  m.q_world_body().y(-0.5);
  m.q_world_body().z(0.25);
  m.yaw_rad(0.5 * i);
  for (size_t k = 0; k < 9; ++k) {
    m.attitude_covariance()[k] = 0.001 * static_cast<double>(k + i);
  }
  m.mag_trusted(i % 3 == 0);
  m.sources_fused(7);
  return m;
}

inline std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}
inline std::string vec_json(const msg::Vector3& v) {
  return "{\"x\":" + num(v.x()) + ",\"y\":" + num(v.y()) + ",\"z\":" + num(v.z()) + "}";
}
inline std::string header_json(const msg::Header& h) {
  return "{\"stamp_ns\":\"" + std::to_string(h.stamp_ns()) + "\",\"seq\":" +
         std::to_string(h.seq()) + ",\"frame_id\":\"" + h.frame_id().to_string() + "\"}";
}
inline const char* b(bool v) { return v ? "true" : "false"; }

inline std::string to_json(const msg::ImuSample& m) {
  return "{\"header\":" + header_json(m.header()) + ",\"sensor_id\":\"" + m.sensor_id().to_string() +
         "\",\"accel_mps2\":" + vec_json(m.accel_mps2()) + ",\"gyro_rps\":" +
         vec_json(m.gyro_rps()) + ",\"mag_ut\":" + vec_json(m.mag_ut()) + ",\"pressure_pa\":" +
         num(m.pressure_pa()) + ",\"temperature_c\":" + num(m.temperature_c()) +
         ",\"valid\":{\"accel\":" + b(m.valid().accel()) + ",\"gyro\":" + b(m.valid().gyro()) +
         ",\"mag\":" + b(m.valid().mag()) + ",\"pressure\":" + b(m.valid().pressure()) +
         ",\"temperature\":" + b(m.valid().temperature()) + "}}";
}

inline std::string to_json(const msg::AttitudeEstimate& m) {
  std::string cov = "[";
  for (size_t k = 0; k < 9; ++k) {
    cov += (k > 0 ? "," : "") + num(m.attitude_covariance()[k]);
  }
  cov += "]";
  const auto& q = m.q_world_body();
  return "{\"header\":" + header_json(m.header()) + ",\"sensor_id\":\"" + m.sensor_id().to_string() +
         "\",\"filter_id\":\"" + m.filter_id().to_string() + "\",\"q_world_body\":{\"w\":" + num(q.w()) +
         ",\"x\":" + num(q.x()) + ",\"y\":" + num(q.y()) + ",\"z\":" + num(q.z()) +
         "},\"yaw_rad\":" + num(m.yaw_rad()) + ",\"attitude_covariance\":" + cov +
         ",\"mag_trusted\":" + b(m.mag_trusted()) + ",\"sources_fused\":" +
         std::to_string(m.sources_fused()) + "}";
}

/// The full serialized payload (encapsulation header included), as DDS puts it on the wire.
template <class PubSubType, class Message>
std::vector<uint8_t> serialize(const Message& message) {
  PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(
      type.getSerializedSizeProvider(const_cast<Message*>(&message))());
  if (!type.serialize(const_cast<Message*>(&message), &payload)) {
    return {};
  }
  return std::vector<uint8_t>(payload.data, payload.data + payload.length);
}

/// The message of a serialized payload; a test failure (and a default message) when it does not
/// deserialize.
template <class PubSubType>
typename PubSubType::type deserialize(const std::vector<uint8_t>& bytes) {
  PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<uint32_t>(bytes.size()));
  std::memcpy(payload.data, bytes.data(), bytes.size());
  payload.length = static_cast<uint32_t>(bytes.size());
  typename PubSubType::type out;
  if (!type.deserialize(&payload, &out)) {
    ADD_FAILURE() << "a payload of " << bytes.size() << " bytes did not deserialize";
  }
  return out;
}

/// One expected message for validate.mjs.
struct ExpectedValue {
  std::string topic;
  uint32_t sequence = 0;
  std::string value_json;
  std::string log_time;      ///< "" = not checked
  std::string publish_time;  ///< "" = not checked
};

/// Writes FILE.expected.json for validate.mjs. CHANNELS_JSON is the "channels" object text.
inline void write_expected(const std::string& mcap_path, int64_t messages, int min_chunks,
                           const std::string& channels_json,
                           const std::vector<ExpectedValue>& values,
                           const std::vector<std::string>& undecodable = {}) {
  const std::string path = mcap_path.substr(0, mcap_path.size() - 5) + ".expected.json";
  std::ofstream out(path);
  out << "{\n";
  if (messages >= 0) {
    out << "\"messages\": " << messages << ",\n";
  }
  out << "\"min_chunks\": " << min_chunks << ",\n\"channels\": " << channels_json
      << ",\n\"undecodable\": [";
  for (size_t i = 0; i < undecodable.size(); ++i) {
    out << (i > 0 ? "," : "") << "\"" << undecodable[i] << "\"";
  }
  out << "],\n\"values\": [\n";
  for (size_t i = 0; i < values.size(); ++i) {
    const ExpectedValue& v = values[i];
    out << "{\"topic\":\"" << v.topic << "\",\"sequence\":" << v.sequence;
    if (!v.log_time.empty()) {
      out << ",\"log_time\":\"" << v.log_time << "\"";
    }
    if (!v.publish_time.empty()) {
      out << ",\"publish_time\":\"" << v.publish_time << "\"";
    }
    out << ",\"value\":" << v.value_json << "}" << (i + 1 < values.size() ? ",\n" : "\n");
  }
  out << "]}\n";
}

/// Waits (bounded: 10 s) until COUNT stops growing for 500 ms.
template <typename Count>
void wait_quiet(Count count) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  uint64_t last = count();
  int stable = 0;
  while (std::chrono::steady_clock::now() < deadline && stable < 5) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const uint64_t now = count();
    stable = now == last ? stable + 1 : 0;
    last = now;
  }
}

/// The project's QoS profiles with the sensor streams made reliable and deep, so that no sample
/// is lost between publisher, component, recorder and replayer on a loaded machine (for tests
/// about reproducing estimates, not about best-effort loss, which test_record_dds covers). The
/// estimates are kept too (transient-local, 1024 deep, 16 instances: a transient-local endpoint's
/// max_samples must hold them all): a reader matches a writer when it has
/// the writer's announcement, the writer sends to it only when it has the reader's, and on a
/// loaded machine the second can come later than the whole run (session 25's fresh-clone run: the
/// recorder matched every estimator, the estimators' 300 estimates each reached it none). The
/// recorder follows a transient-local writer with a transient-local reader and gets its history.
/// Returns the file path (in DIR).
inline std::string lossless_profiles(const std::string& dir) {
  std::ifstream in(poise::testing::source_path("config/qos/poise_profiles.xml"));
  std::ostringstream text;
  text << in.rdbuf();
  std::string xml = text.str();
  auto replace_all = [&xml](const std::string& from, const std::string& to) {
    for (size_t at = xml.find(from); at != std::string::npos; at = xml.find(from, at + to.size())) {
      xml.replace(at, from.size(), to);
    }
  };
  replace_all("<kind>BEST_EFFORT</kind>", "<kind>RELIABLE</kind>");
  replace_all("<depth>32</depth>", "<depth>4096</depth>");
  // the estimate profiles (writer and reader) alone: durability and depth
  for (size_t at = xml.find("profile_name=\"estimate\""); at != std::string::npos;
       at = xml.find("profile_name=\"estimate\"", at + 1)) {
    const size_t end = xml.find("</data_", at);
    std::string block = xml.substr(at, end - at);
    for (const auto& [from, to] : std::vector<std::pair<std::string, std::string>>{
             {"<kind>VOLATILE</kind>", "<kind>TRANSIENT_LOCAL</kind>"},
             {"<depth>64</depth>", "<depth>1024</depth>"},
             {"<max_instances>256</max_instances>", "<max_instances>16</max_instances>"},
             {"<max_samples_per_instance>64</max_samples_per_instance>",
              "<max_samples_per_instance>1024</max_samples_per_instance>"}}) {
      const size_t p = block.find(from);
      if (p != std::string::npos) {
        block.replace(p, from.size(), to);
      }
    }
    xml.replace(at, end - at, block);
  }
  const std::string path = dir + "/lossless_profiles.xml";
  std::ofstream(path) << xml;
  return path;
}

/// A fresh directory for validator cases under the build tree.
inline std::string cases_dir(const std::string& name) {
  const std::string dir = std::string(POISE_RECORD_VALIDATOR_DIR) + "/cases-" + name;
  const std::string cmd = "rm -rf '" + dir + "' && mkdir -p '" + dir + "'";
  if (std::system(cmd.c_str()) != 0) {
    return "";
  }
  return dir;
}

using poise::testing::find_on_path;

struct NodeValidation {
  std::string skip_reason;  ///< non-empty: could not run (no node/npm, install failed)
  int exit_code = -1;
  std::string output;
};

/// Installs the validator's npm packages into the build tree once (under a lock), then runs
/// validate.mjs on DIR.
inline NodeValidation run_node_validator(const std::string& dir) {
  using namespace std::chrono_literals;
  NodeValidation result;
  const std::string vdir = POISE_RECORD_VALIDATOR_DIR;
  result.skip_reason = poise::testing::npm_install(
      vdir, {"@mcap/core", "@mcap/nodejs", "@foxglove/omgidl-parser", "@foxglove/omgidl-serialization",
             "@foxglove/crc", "fzstd"});
  if (!result.skip_reason.empty()) {
    return result;
  }
  const auto run = poise::testing::run({find_on_path("node"), vdir + "/validate.mjs", dir}, 120s);
  result.exit_code = run.exit_code;
  result.output = run.output;
  return result;
}

}  // namespace poise::record::testing
