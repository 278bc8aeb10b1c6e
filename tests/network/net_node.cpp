// poise_net_node: the processes of the multi-host network tests (tests/network). One binary, one
// role per run, each printing machine-readable events ("@name key=value ...") on stdout:
//   imu      publishes msg::ImuSample on `imu` at --rate-hz (IMU host; fields from net_samples.h)
//   camera   publishes msg::VisionPose on `vision_pose` at --rate-hz (camera host)
//   fusion   subscribes `imu` (+ `vision_pose`) and publishes msg::AttitudeEstimate on
//            `attitude/<filter-id>` for every IMU sample (fusion host; an accelerometer-tilt relay
//            standing in for `poise parallel-kf` until that node exists)
//   watch    subscribes a topic and reports arrivals, sequence gaps and restarts (recorder host);
//            --type diagnostics prints every FilterDiagnostics as "@diag source=... counter=N ..."
//   capture  counts UDP/RTPS packets on an interface and those containing a byte marker (root)
//   pose     publishes msg::PoseEstimate on `pose/<filter-id>` (fields from net_samples.h)
// Events: @start, @matched, @first, @resume (data again after >= --silence-ms), @summary (on exit).
// Times are CLOCK_MONOTONIC ns (the same clock in every network namespace of the machine).
// Security and the participant profile come from the environment (POISE_SECURITY_DIR/IDENTITY,
// POISE_DDS_PROFILE, ROS_DISCOVERY_SERVER) exactly as for every poise process.
#include "net_samples.h"

#include "poise/dds/participant.h"
#include "poise/dds/sequence_gaps.h"

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <CLI/CLI.hpp>

#include <arpa/inet.h>
#include <linux/if_packet.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <netinet/ip.h>
#include <netinet/udp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdarg>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>

namespace {

namespace msg = poise::msg;
namespace dds = poise::dds;
namespace nt = poise::nettest;

std::atomic<bool> g_stop{false};
void on_signal(int /*sig*/) { g_stop.store(true); }

int64_t now_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

std::mutex g_print_mutex;
/// Prints one event line and flushes (the tests read the output while the process runs).
__attribute__((format(printf, 1, 2))) void event(const char* format, ...) {
  std::lock_guard<std::mutex> lock(g_print_mutex);
  va_list args;
  va_start(args, format);
  std::vprintf(format, args);
  va_end(args);
  std::fflush(stdout);
}

/// Runs until SIGINT/SIGTERM or `duration_s` (0: no limit) elapses.
void run_until_stopped(double duration_s, const std::function<void()>& tick = {},
                       double tick_hz = 0.0) {
  const int64_t start = now_ns();
  const int64_t end = duration_s > 0.0 ? start + static_cast<int64_t>(duration_s * 1e9) : 0;
  const int64_t period = tick_hz > 0.0 ? static_cast<int64_t>(1e9 / tick_hz) : 10000000;
  int64_t next = start;
  while (!g_stop.load() && (end == 0 || now_ns() < end)) {
    if (tick) {
      tick();
    }
    next += period;
    const int64_t wait = next - now_ns();
    if (wait > 0) {
      std::this_thread::sleep_for(std::chrono::nanoseconds(wait));
    } else {
      next = now_ns();  // fell behind: do not burst
    }
  }
}

/// Per-source arrival events on top of poise::dds::SequenceGaps: @first, @resume after a silence
/// or a publisher restart (with the samples lost in that gap), @summary with the totals.
class StreamStats {
 public:
  StreamStats(std::string topic, double silence_ms)
      : topic_(std::move(topic)), silence_ns_(static_cast<int64_t>(silence_ms * 1e6)) {}

  /// `stamp_ns`: the sample's header stamp (same host clock here), to report the age of the first
  /// sample after a silence (stale data queued during an outage shows as a large age).
  void on_sample(const std::string& source, uint32_t seq, const std::string& writer,
                 int64_t stamp_ns) {
    const int64_t t = now_ns();
    std::lock_guard<std::mutex> lock(mutex_);
    const dds::SequenceGaps::Event e = gaps_.on_sample(source, seq, writer);
    int64_t& last = last_ns_[source];
    if (e.first) {
      event("@first topic=%s source=%s seq=%u t_ns=%lld\n", topic_.c_str(), source.c_str(), seq,
            static_cast<long long>(t));
    } else if (!e.duplicate && (t - last >= silence_ns_ || e.restart)) {
      event("@resume topic=%s source=%s seq=%u t_ns=%lld silence_ms=%.1f lost=%llu restart=%d "
            "age_ms=%.1f\n",
            topic_.c_str(), source.c_str(), seq, static_cast<long long>(t),
            static_cast<double>(t - last) * 1e-6, static_cast<unsigned long long>(e.lost),
            e.restart ? 1 : 0, static_cast<double>(t - stamp_ns) * 1e-6);
    }
    last = t;
  }

  void print_summary() {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& [source, s] : gaps_.by_source()) {
      event("@summary topic=%s source=%s received=%llu lost=%llu gaps=%llu restarts=%llu\n",
            topic_.c_str(), source.c_str(), static_cast<unsigned long long>(s.received),
            static_cast<unsigned long long>(s.lost), static_cast<unsigned long long>(s.gaps),
            static_cast<unsigned long long>(s.restarts));
    }
    if (gaps_.by_source().empty()) {
      event("@summary topic=%s source=none received=0 lost=0 gaps=0 restarts=0\n", topic_.c_str());
    }
  }

 private:
  std::string topic_;
  int64_t silence_ns_;
  std::mutex mutex_;
  dds::SequenceGaps gaps_;
  std::map<std::string, int64_t> last_ns_;
};

/// Reports changes of an endpoint's matched count.
template <typename Endpoint>
void report_matches(const Endpoint& endpoint, const std::string& topic, int& last) {
  const int m = endpoint.matched();
  if (m != last) {
    event("@matched topic=%s count=%d t_ns=%lld\n", topic.c_str(), m,
          static_cast<long long>(now_ns()));
    last = m;
  }
}

struct Common {
  int domain = 0;
  double duration_s = 0.0;
  double rate_hz = 200.0;
  std::string sensor_id = "imu0";
  std::string topic;
  double silence_ms = 200.0;
};

dds::Participant make_participant(const Common& c, const std::string& name) {
  event("@start role=%s pid=%d t_ns=%lld\n", name.c_str(), static_cast<int>(::getpid()),
        static_cast<long long>(now_ns()));
  return dds::Participant({c.domain, "", "", "poise_net_" + name});
}

void fill_imu(msg::ImuSample& m, const std::string& sensor_id, uint32_t seq) {
  const nt::ImuValues v = nt::imu_values(seq);
  m.header().stamp_ns(now_ns());
  m.header().seq(seq);
  m.header().frame_id("body");
  m.sensor_id(sensor_id);
  m.accel_mps2().x(v.accel_mps2[0]);
  m.accel_mps2().y(v.accel_mps2[1]);
  m.accel_mps2().z(v.accel_mps2[2]);
  m.gyro_rps().x(v.gyro_rps[0]);
  m.gyro_rps().y(v.gyro_rps[1]);
  m.gyro_rps().z(v.gyro_rps[2]);
  m.mag_ut().x(v.mag_ut[0]);
  m.mag_ut().y(v.mag_ut[1]);
  m.mag_ut().z(v.mag_ut[2]);
  m.pressure_pa(v.pressure_pa);
  m.temperature_c(v.temperature_c);
  m.valid().accel(true);
  m.valid().gyro(true);
  m.valid().mag(true);
  m.valid().pressure(true);
  m.valid().temperature(false);
}

void fill_vision(msg::VisionPose& m, const std::string& sensor_id, uint32_t seq) {
  const nt::VisionValues v = nt::vision_values(seq);
  const int64_t t = now_ns();
  m.header().stamp_ns(t);
  m.header().seq(seq);
  m.header().frame_id("world");
  m.sensor_id(sensor_id);
  m.capture_stamp_ns(t);
  m.pose_world_camera().position_m().x(v.position_m[0]);
  m.pose_world_camera().position_m().y(v.position_m[1]);
  m.pose_world_camera().position_m().z(v.position_m[2]);
  m.pose_world_camera().orientation().w(v.q_wxyz[0]);
  m.pose_world_camera().orientation().x(v.q_wxyz[1]);
  m.pose_world_camera().orientation().y(v.q_wxyz[2]);
  m.pose_world_camera().orientation().z(v.q_wxyz[3]);
  m.body_valid(false);
  m.covariance().fill(0.0);
  for (size_t i = 0; i < 6; ++i) {
    m.covariance()[i * 7] = v.covariance_diag;
  }
  m.reprojection_rms_px(v.reprojection_rms_px);
  m.tag_ids().assign(v.tag_ids.begin(), v.tag_ids.end());
}

int run_imu(const Common& c) {
  dds::Participant participant = make_participant(c, "imu");
  const std::string topic = c.topic.empty() ? "imu" : c.topic;
  dds::Writer<msg::ImuSamplePubSubType> writer(participant, topic);
  uint32_t seq = 0;
  int matched = -1;
  msg::ImuSample m;
  int64_t max_write_ns = 0;
  uint64_t slow_writes = 0;  // write() calls over 1 ms: they would stall a driver's read loop
  run_until_stopped(
      c.duration_s,
      [&] {
        report_matches(writer, topic, matched);
        fill_imu(m, c.sensor_id, seq++);
        const int64_t t0 = now_ns();
        writer.write(m);
        const int64_t took = now_ns() - t0;
        max_write_ns = std::max(max_write_ns, took);
        slow_writes += took > 1000000 ? 1U : 0U;
      },
      c.rate_hz);
  event("@summary topic=%s sent=%u t_ns=%lld max_write_us=%lld slow_writes=%llu\n", topic.c_str(),
        seq, static_cast<long long>(now_ns()), static_cast<long long>(max_write_ns / 1000),
        static_cast<unsigned long long>(slow_writes));
  return 0;
}

int run_camera(const Common& c) {
  dds::Participant participant = make_participant(c, "camera");
  const std::string topic = c.topic.empty() ? "vision_pose" : c.topic;
  dds::Writer<msg::VisionPosePubSubType> writer(participant, topic);
  uint32_t seq = 0;
  int matched = -1;
  msg::VisionPose m;
  run_until_stopped(
      c.duration_s,
      [&] {
        report_matches(writer, topic, matched);
        fill_vision(m, c.sensor_id, seq++);
        writer.write(m);
      },
      c.rate_hz);
  event("@summary topic=%s sent=%u\n", topic.c_str(), seq);
  return 0;
}

void fill_pose(msg::PoseEstimate& m, const std::string& sensor_id, const std::string& filter_id,
               uint32_t seq) {
  const nt::PoseValues v = nt::pose_values(seq);
  m.header().stamp_ns(now_ns());
  m.header().seq(seq);
  m.header().frame_id("world");
  m.sensor_id(sensor_id);
  m.filter_id(filter_id);
  m.position_m().x(v.position_m[0]);
  m.position_m().y(v.position_m[1]);
  m.position_m().z(v.position_m[2]);
  m.q_world_body().w(v.q_wxyz[0]);
  m.q_world_body().x(v.q_wxyz[1]);
  m.q_world_body().y(v.q_wxyz[2]);
  m.q_world_body().z(v.q_wxyz[3]);
  for (size_t r = 0; r < 9; ++r) {
    for (size_t col = 0; col < 9; ++col) {
      m.covariance()[r * 9 + col] = nt::pose_covariance(r, col);
    }
  }
  m.sources_fused(msg::SOURCE_ACCEL | msg::SOURCE_VISION);
}

int run_pose(const Common& c, const std::string& filter_id) {
  dds::Participant participant = make_participant(c, "pose");
  const std::string topic = c.topic.empty() ? dds::TopicNames{}.pose(filter_id) : c.topic;
  dds::Writer<msg::PoseEstimatePubSubType> writer(participant, topic);
  uint32_t seq = 0;
  int matched = -1;
  msg::PoseEstimate m;
  run_until_stopped(
      c.duration_s,
      [&] {
        report_matches(writer, topic, matched);
        fill_pose(m, c.sensor_id, filter_id, seq++);
        writer.write(m);
      },
      c.rate_hz);
  event("@summary topic=%s sent=%u t_ns=%lld\n", topic.c_str(), seq,
        static_cast<long long>(now_ns()));
  return 0;
}

int run_fusion(const Common& c, const std::string& filter_id) {
  dds::Participant participant = make_participant(c, "fusion");
  const std::string in_topic = c.topic.empty() ? "imu" : c.topic;
  const std::string out_topic = dds::TopicNames{}.attitude(filter_id);
  dds::Writer<msg::AttitudeEstimatePubSubType> writer(participant, out_topic);
  StreamStats imu_stats(in_topic, c.silence_ms);
  StreamStats vision_stats("vision_pose", c.silence_ms);
  std::mutex out_mutex;
  uint32_t out_seq = 0;
  msg::AttitudeEstimate out;
  dds::Reader<msg::ImuSamplePubSubType> imu_reader(
      participant, in_topic, [&](const msg::ImuSample& in, const auto& info) {
        imu_stats.on_sample(in.sensor_id().to_string(), in.header().seq(), dds::writer_key(info),
                            in.header().stamp_ns());
        const double ax = in.accel_mps2().x();
        const double ay = in.accel_mps2().y();
        const double az = in.accel_mps2().z();
        const double roll = std::atan2(ay, az);
        const double pitch = std::atan2(-ax, std::sqrt(ay * ay + az * az));
        const double cr = std::cos(roll / 2), sr = std::sin(roll / 2);
        const double cp = std::cos(pitch / 2), sp = std::sin(pitch / 2);
        std::lock_guard<std::mutex> lock(out_mutex);
        out.header().stamp_ns(in.header().stamp_ns());
        out.header().seq(out_seq++);
        out.header().frame_id("world");
        out.sensor_id(in.sensor_id());
        out.filter_id(filter_id);
        out.q_world_body().w(cr * cp);
        out.q_world_body().x(sr * cp);
        out.q_world_body().y(cr * sp);
        out.q_world_body().z(-sr * sp);
        out.roll_rad(roll);
        out.pitch_rad(pitch);
        out.yaw_rad(0.0);
        out.sources_fused(msg::SOURCE_ACCEL);
        writer.write(out);
      });
  dds::Reader<msg::VisionPosePubSubType> vision_reader(
      participant, "vision_pose", [&](const msg::VisionPose& in, const auto& info) {
        vision_stats.on_sample(in.sensor_id().to_string(), in.header().seq(), dds::writer_key(info),
                               in.header().stamp_ns());
      });
  int matched_in = -1;
  int matched_out = -1;
  run_until_stopped(c.duration_s, [&] {
    report_matches(imu_reader, in_topic, matched_in);
    report_matches(writer, out_topic, matched_out);
  });
  imu_stats.print_summary();
  vision_stats.print_summary();
  return 0;
}

int run_watch(const Common& c, const std::string& type) {
  dds::Participant participant = make_participant(c, "watch");
  const std::string topic =
      !c.topic.empty() ? c.topic : (type == "imu" ? "imu" : type == "vision_pose" ? "vision_pose"
                                                                                   : "attitude/tilt");
  StreamStats stats(topic, c.silence_ms);
  int matched = -1;
  auto watch = [&](auto& reader) {
    run_until_stopped(c.duration_s, [&] { report_matches(reader, topic, matched); });
  };
  if (type == "imu") {
    dds::Reader<msg::ImuSamplePubSubType> reader(
        participant, topic, [&](const msg::ImuSample& m, const auto& info) {
          stats.on_sample(m.sensor_id().to_string(), m.header().seq(), dds::writer_key(info),
                          m.header().stamp_ns());
        });
    watch(reader);
  } else if (type == "diagnostics") {
    // Every diagnostics message as one line: @diag source component t_ns + counters + metrics.
    dds::Reader<msg::FilterDiagnosticsPubSubType> reader(
        participant, c.topic.empty() ? "diagnostics" : c.topic,
        [&](const msg::FilterDiagnostics& m, const auto& /*info*/) {
          std::string line = "@diag source=" + m.sensor_id().to_string() +
                             " component=" + m.component_name().to_string() +
                             " seq=" + std::to_string(m.header().seq()) +
                             " t_ns=" + std::to_string(now_ns());
          for (const auto& k : m.counters()) {
            line += " " + k.name().to_string() + "=" + std::to_string(k.value());
          }
          char value[64];
          for (const auto& k : m.metrics()) {
            std::snprintf(value, sizeof value, "=%.6g", k.value());
            line += " " + k.name().to_string() + value;
          }
          event("%s\n", line.c_str());
        });
    watch(reader);
    return 0;
  } else if (type == "vision_pose") {
    dds::Reader<msg::VisionPosePubSubType> reader(
        participant, topic, [&](const msg::VisionPose& m, const auto& info) {
          stats.on_sample(m.sensor_id().to_string(), m.header().seq(), dds::writer_key(info),
                          m.header().stamp_ns());
        });
    watch(reader);
  } else {
    dds::Reader<msg::AttitudeEstimatePubSubType> reader(
        participant, topic, [&](const msg::AttitudeEstimate& m, const auto& info) {
          stats.on_sample(m.sensor_id().to_string(), m.header().seq(), dds::writer_key(info),
                          m.header().stamp_ns());
        });
    watch(reader);
  }
  stats.print_summary();
  return 0;
}

/// Counts packets on `iface` (AF_PACKET, needs root; both directions): UDP ones, RTPS ones, and per
/// marker those containing it anywhere (also across the boundary with the previous packet, so a
/// string split between two IP fragments of one datagram is still found). The first marker's
/// counts go in @capture (marker, rtps_marker); every marker's in "@seen index=I packets=N".
int run_capture(const std::string& iface, double duration_s, const std::vector<std::string>& markers) {
  const int fd = ::socket(AF_PACKET, SOCK_DGRAM, htons(ETH_P_ALL));
  if (fd < 0) {
    std::fprintf(stderr, "capture: socket(AF_PACKET) failed: %s (needs root)\n", std::strerror(errno));
    return 1;
  }
  sockaddr_ll addr{};
  addr.sll_family = AF_PACKET;
  addr.sll_protocol = htons(ETH_P_ALL);
  addr.sll_ifindex = static_cast<int>(::if_nametoindex(iface.c_str()));
  if (addr.sll_ifindex == 0 ||
      ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    std::fprintf(stderr, "capture: cannot bind to interface %s: %s\n", iface.c_str(),
                 std::strerror(errno));
    ::close(fd);
    return 1;
  }
  timeval tv{0, 100000};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  event("@start role=capture pid=%d t_ns=%lld\n", static_cast<int>(::getpid()),
        static_cast<long long>(now_ns()));
  uint64_t packets = 0, udp = 0, rtps = 0, with_marker = 0, rtps_with_marker = 0;
  std::vector<uint64_t> seen(markers.size(), 0);
  constexpr size_t kCarry = 256;  // longer than any marker
  std::string previous_tail;
  std::string buffer(65536, '\0');
  const int64_t end = now_ns() + static_cast<int64_t>(duration_s * 1e9);
  while (!g_stop.load() && now_ns() < end) {
    const ssize_t n = ::recv(fd, buffer.data(), buffer.size(), 0);
    if (n <= 0) {
      continue;
    }
    ++packets;
    const std::string_view packet(buffer.data(), static_cast<size_t>(n));
    const std::string joined = previous_tail + std::string(packet);
    previous_tail = joined.substr(joined.size() > kCarry ? joined.size() - kCarry : 0);
    for (size_t i = 0; i < markers.size(); ++i) {
      seen[i] += joined.find(markers[i]) != std::string::npos ? 1U : 0U;
    }
    const bool has_marker = !markers.empty() && packet.find(markers[0]) != std::string_view::npos;
    with_marker += has_marker ? 1U : 0U;
    if (packet.size() < sizeof(iphdr)) {
      continue;
    }
    iphdr ip{};
    std::memcpy(&ip, packet.data(), sizeof(ip));
    const size_t ihl = static_cast<size_t>(ip.ihl) * 4U;
    if (ip.version != 4 || ip.protocol != IPPROTO_UDP || packet.size() < ihl + sizeof(udphdr)) {
      continue;
    }
    ++udp;
    const std::string_view payload = packet.substr(ihl + sizeof(udphdr));
    if (payload.substr(0, 4) == "RTPS") {
      ++rtps;
      rtps_with_marker += has_marker ? 1U : 0U;
    }
  }
  ::close(fd);
  event("@capture iface=%s packets=%llu udp=%llu rtps=%llu marker=%llu rtps_marker=%llu\n",
        iface.c_str(), static_cast<unsigned long long>(packets),
        static_cast<unsigned long long>(udp), static_cast<unsigned long long>(rtps),
        static_cast<unsigned long long>(with_marker),
        static_cast<unsigned long long>(rtps_with_marker));
  for (size_t i = 0; i < markers.size(); ++i) {
    event("@seen index=%zu packets=%llu\n", i, static_cast<unsigned long long>(seen[i]));
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  CLI::App app{"poise_net_node: test peer for the multi-host network tests (tests/network)"};
  app.require_subcommand(1);
  Common c;
  std::string filter_id = "tilt";
  std::string type = "imu";
  std::string iface = "eth0";
  std::vector<std::string> markers{nt::kMarkerSensorId};
  auto add_common = [&](CLI::App* sub) {
    sub->add_option("--domain", c.domain, "DDS domain id")->check(CLI::Range(0, 232));
    sub->add_option("--duration-s", c.duration_s, "stop after this many seconds (0: until signal)");
    sub->add_option("--topic", c.topic, "topic name (default per role)");
    sub->add_option("--silence-ms", c.silence_ms, "report @resume after a silence this long");
  };
  auto* imu = app.add_subcommand("imu", "publish ImuSample on `imu`");
  add_common(imu);
  imu->add_option("--rate-hz", c.rate_hz, "publish rate")->check(CLI::Range(1.0, 2000.0));
  imu->add_option("--sensor-id", c.sensor_id, "sensor_id of the samples");
  auto* camera = app.add_subcommand("camera", "publish VisionPose on `vision_pose`");
  add_common(camera);
  camera->add_option("--rate-hz", c.rate_hz, "publish rate")->check(CLI::Range(1.0, 2000.0));
  camera->add_option("--sensor-id", c.sensor_id, "sensor_id of the samples");
  auto* fusion = app.add_subcommand("fusion", "relay imu -> attitude/<filter-id>");
  add_common(fusion);
  fusion->add_option("--filter-id", filter_id, "filter id of the output topic");
  auto* pose = app.add_subcommand("pose", "publish PoseEstimate on `pose/<filter-id>`");
  add_common(pose);
  pose->add_option("--rate-hz", c.rate_hz, "publish rate")->check(CLI::Range(1.0, 2000.0));
  pose->add_option("--sensor-id", c.sensor_id, "sensor_id of the samples");
  pose->add_option("--filter-id", filter_id, "filter id of the topic");
  auto* watch = app.add_subcommand("watch", "report arrivals and sequence gaps on a topic");
  add_common(watch);
  watch->add_option("--type", type, "message type")
      ->check(CLI::IsMember({"imu", "attitude", "vision_pose", "diagnostics"}));
  auto* capture = app.add_subcommand("capture", "count packets carrying a marker (root)");
  capture->add_option("--iface", iface, "interface");
  capture->add_option("--duration-s", c.duration_s, "capture time")->required();
  capture->add_option("--marker", markers, "byte strings to look for (repeatable; default the "
                                           "IMU sensor_id marker)");
  c.rate_hz = 200.0;
  CLI11_PARSE(app, argc, argv);
  if (camera->parsed() && c.sensor_id == "imu0") {
    c.sensor_id = "cam0";
  }
  try {
    if (imu->parsed()) {
      return run_imu(c);
    }
    if (camera->parsed()) {
      return run_camera(c);
    }
    if (fusion->parsed()) {
      return run_fusion(c, filter_id);
    }
    if (pose->parsed()) {
      return run_pose(c, filter_id);
    }
    if (watch->parsed()) {
      return run_watch(c, type);
    }
    return run_capture(iface, c.duration_s, markers);
  } catch (const std::exception& e) {
    event("@error what=\"%s\"\n", e.what());
    std::fprintf(stderr, "poise_net_node: error: %s\n", e.what());
    return 1;
  }
}
