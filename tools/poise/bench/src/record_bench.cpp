#include "poise/bench/record_bench.h"

#include "poise/cli/common.h"
#include "poise/dds/participant.h"
#include "poise/eval/filter_registry.h"
#include "poise/process/process.h"
#include "poise/record/idl_schema.h"
#include "poise/record/recorder.h"
#include "poise/record/replayer.h"

#include <poise/msg/imuPubSubTypes.h>

#include <CLI/CLI.hpp>
#include <fastdds/rtps/common/SerializedPayload.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace poise::record {

namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

msg::ImuSample bench_sample(uint32_t i, int64_t stamp_ns) {
  msg::ImuSample m;
  m.header().stamp_ns(stamp_ns);
  m.header().seq(i);
  m.header().frame_id("body");
  m.sensor_id("imu0");
  m.accel_mps2().x(0.01 * i);
  m.accel_mps2().z(9.81);
  m.gyro_rps().y(0.001 * i);
  m.mag_ut().x(20.0);
  m.valid().accel(true);
  m.valid().gyro(true);
  m.valid().mag(true);
  return m;
}

std::vector<uint8_t> serialize(const msg::ImuSample& m) {
  msg::ImuSamplePubSubType type;
  auto* data = const_cast<msg::ImuSample*>(&m);
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.getSerializedSizeProvider(data)());
  type.serialize(data, &payload);
  return std::vector<uint8_t>(payload.data, payload.data + payload.length);
}

std::string temp_path(const std::string& what) {
  return (std::filesystem::temp_directory_path() /
          ("poise-bench-" + what + "-" + std::to_string(::getpid()) + ".mcap"))
      .string();
}

/// Writes SECONDS of 1 kHz ImuSample on TOPIC into PATH; returns the message count.
uint64_t write_imu_recording(const std::string& path, const std::string& topic, double seconds,
                             Compression compression) {
  WriterOptions opt;
  opt.compression = compression;
  int64_t clock = 0;
  opt.clock = [&clock] { return clock; };
  McapWriter w(open_file_sink(path), opt);
  const std::string idl = *flattened_idl("poise::msg::ImuSample");
  const uint16_t schema =
      w.add_schema("poise::msg::ImuSample", "omgidl", std::vector<uint8_t>(idl.begin(), idl.end()));
  const uint16_t ch = w.add_channel(schema, topic, "cdr",
                                    {{"dds_type", "poise::msg::ImuSample"},
                                     {"reliability", "BEST_EFFORT"},
                                     {"durability", "VOLATILE"},
                                     {"qos_profile", "sensor"}});
  const auto n = static_cast<uint64_t>(seconds * 1000.0);
  const int64_t t0 = 1'700'000'000'000'000'000LL;
  for (uint64_t i = 0; i < n; ++i) {
    const int64_t stamp = t0 + static_cast<int64_t>(i) * 1'000'000;
    clock = static_cast<int64_t>(i) * 1'000'000;
    const auto bytes = serialize(bench_sample(static_cast<uint32_t>(i), stamp));
    w.write(ch, static_cast<uint32_t>(i), static_cast<uint64_t>(stamp + 100'000),
            static_cast<uint64_t>(stamp), bytes.data(), bytes.size());
  }
  w.close();
  return n;
}

}  // namespace

void bench_record(const BenchRecordOptions& options, std::ostream& out) {
  char line[256];
  // 1. The MCAP writer alone (file on the temp directory's file system).
  out << "MCAP writer alone (ImuSample payloads, file in " << std::filesystem::temp_directory_path().string()
      << "):\n";
  for (Compression c : {Compression::kNone, Compression::kZstd}) {
    if (c == Compression::kZstd && !zstd_available()) {
      continue;
    }
    const std::string path = temp_path("writer");
    const auto t0 = Clock::now();
    const uint64_t n = write_imu_recording(path, "imu", 300.0, c);
    const double dt = since(t0);
    const double mb = static_cast<double>(std::filesystem::file_size(path)) / 1e6;
    std::snprintf(line, sizeof(line), "  %-5s %9.0f msg/s  %7.1f MB/s written  (%llu msgs, %.1f MB)\n",
                  c == Compression::kZstd ? "zstd" : "none", static_cast<double>(n) / dt, mb / dt,
                  static_cast<unsigned long long>(n), mb);
    out << line;
    std::filesystem::remove(path);
  }
  // 2. DDS publisher -> recorder, rising rates.
  const std::string topic = "bench/record_imu";
  const std::string path = temp_path("record");
  std::ostringstream recorder_log;
  RecorderOptions ro;
  ro.output = path;
  ro.topics = {topic};
  ro.domain = options.domain;
  ro.participant_profile = options.profile;
  ro.log = &recorder_log;
  Recorder recorder(ro);
  RecorderStats final_stats;
  std::thread thread([&] { final_stats = recorder.run(); });
  dds::Participant participant({options.domain, options.profile, "", "poise bench publisher"});
  dds::Writer<msg::ImuSamplePubSubType> writer(participant, topic, dds::QosKind::kSensor);
  const auto wait_start = Clock::now();
  while ((recorder.subscribed() < 1 || writer.matched() < 1) && since(wait_start) < 15.0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (recorder.subscribed() < 1 || writer.matched() < 1) {
    recorder.request_stop();
    thread.join();
    std::filesystem::remove(path);
    throw dds::DdsError("the recorder did not match the benchmark publisher within 15 s on "
                        "domain " + std::to_string(options.domain) + " (profile " +
                        options.profile + ")");
  }
  out << "DDS (best-effort ImuSample, profile " << options.profile << ") -> poise record -> MCAP:\n";
  out << "  target msg/s   published msg/s   recorded      lost\n";
  uint32_t seq = 0;
  double best_without_loss = 0.0;
  for (int rate : {1000, 2000, 5000, 10000, 20000, 50000, 100000, 200000}) {
    const uint64_t before = recorder.written();
    const auto n = static_cast<uint64_t>(rate * options.seconds_per_step);
    const auto t0 = Clock::now();
    uint64_t sent = 0;
    msg::ImuSample m = bench_sample(0, 0);
    while (sent < n) {
      // Pace in 1 ms slots.
      const uint64_t due = std::min<uint64_t>(
          n, static_cast<uint64_t>(since(t0) * rate) + static_cast<uint64_t>(rate / 1000 + 1));
      for (; sent < due; ++sent) {
        m.header().seq(seq++);
        m.header().stamp_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                Clock::now().time_since_epoch())
                                .count());
        writer.write(m);
      }
      std::this_thread::sleep_until(t0 + std::chrono::microseconds(
                                             static_cast<int64_t>(1e6 * static_cast<double>(sent) / rate)));
    }
    const double achieved = static_cast<double>(n) / since(t0);
    // Let the recorder drain (bounded).
    const auto drain = Clock::now();
    uint64_t recorded = recorder.written() - before;
    while (recorded < n && since(drain) < 2.0) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      recorded = recorder.written() - before;
    }
    const uint64_t lost = n - std::min(n, recorded);
    std::snprintf(line, sizeof(line), "  %12d   %15.0f   %8llu  %8llu (%.2f%%)\n", rate, achieved,
                  static_cast<unsigned long long>(recorded), static_cast<unsigned long long>(lost),
                  100.0 * static_cast<double>(lost) / static_cast<double>(n));
    out << line << std::flush;
    if (lost == 0) {
      best_without_loss = std::max(best_without_loss, achieved);
    } else if (static_cast<double>(lost) > 0.01 * static_cast<double>(n)) {
      break;
    }
  }
  recorder.request_stop();
  thread.join();
  std::snprintf(line, sizeof(line),
                "highest rate recorded without loss: %.0f msg/s (queue drops %llu, DDS sequence "
                "gaps %llu)\n",
                best_without_loss, static_cast<unsigned long long>(final_stats.dropped_queue_full),
                static_cast<unsigned long long>(final_stats.sequence_gaps));
  out << line;
  std::filesystem::remove(path);
}

void bench_replay(const BenchReplayOptions& options, std::ostream& out) {
  char line[256];
  const std::string path = temp_path("replay");
  const uint64_t n = write_imu_recording(path, "bench/replay_imu", options.recording_s,
                                         Compression::kNone);
  std::snprintf(line, sizeof(line), "recording: %.0f s of 1 kHz ImuSample (%llu messages, %.1f MB)\n",
                options.recording_s, static_cast<unsigned long long>(n),
                static_cast<double>(std::filesystem::file_size(path)) / 1e6);
  out << line;
  // Reader alone.
  {
    const auto t0 = Clock::now();
    const McapReader reader = McapReader::open_file(path);
    MessageCursor cursor = reader.messages();
    uint64_t count = 0;
    uint64_t checksum = 0;
    while (const MessageView* m = cursor.next()) {
      checksum += m->size > 4 ? m->data[4] : 0;  // touch the payload (stamp byte)
      ++count;
    }
    const double dt = since(t0);
    std::snprintf(line, sizeof(line),
                  "reader alone:            %8.1f x real time (%llu msgs in %.3f s, checksum %llu)\n",
                  options.recording_s / dt, static_cast<unsigned long long>(count), dt,
                  static_cast<unsigned long long>(checksum));
    out << line;
  }
  // Offline processing (no DDS): the parallel KF over the same recording.
  {
    std::vector<ProcessFilter> filters;
    filters.push_back({"parallel_kf", eval::make_filter("parallel_kf"), {}});
    ProcessOptions po;
    po.input = path;
    po.output = temp_path("processed");
    po.topics.imu = "bench/replay_imu";
    const auto t0 = Clock::now();
    const ProcessStats ps = process_recording(po, filters);
    const double dt = since(t0);
    std::snprintf(line, sizeof(line),
                  "poise process (parallel_kf): %8.1f x real time (%llu samples, %llu estimates "
                  "in %.3f s)\n",
                  options.recording_s / dt, static_cast<unsigned long long>(ps.imu_samples),
                  static_cast<unsigned long long>(ps.estimates.at("parallel_kf")), dt);
    out << line;
    std::filesystem::remove(po.output);
  }
  // Over DDS, as fast as possible, into a best-effort subscriber.
  dds::Participant participant({options.domain, options.profile, "", "poise bench subscriber"});
  std::atomic<uint64_t> received{0};
  dds::Reader<msg::ImuSamplePubSubType> reader(
      participant, "bench/replay_imu", dds::QosKind::kSensor,
      [&received](const msg::ImuSample&, const eprosima::fastdds::dds::SampleInfo&) {
        received.fetch_add(1);
      });
  ReplayOptions ro;
  ro.input = path;
  ro.domain = options.domain;
  ro.participant_profile = options.profile;
  ro.schedule.as_fast_as_possible = true;
  ro.wait_for_subscribers_s = 15.0;
  std::ostringstream log;
  ro.log = &log;
  const ReplayStats stats = replay(ro);
  const auto wait = Clock::now();
  while (received.load() < stats.schedule.delivered && since(wait) < 2.0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::snprintf(line, sizeof(line),
                "DDS, as fast as possible: %8.1f x real time (%llu published in %.3f s; %llu "
                "received by a best-effort subscriber)\n",
                stats.schedule.recorded_span_s / stats.schedule.elapsed_s,
                static_cast<unsigned long long>(stats.schedule.delivered), stats.schedule.elapsed_s,
                static_cast<unsigned long long>(received.load()));
  out << line;
  std::filesystem::remove(path);
}

}  // namespace poise::record

namespace poise::cli {

void register_bench_record(CLI::App& app) {
  CLI::App* bench = subcommand_group(app, "bench", "Benchmarks (figures printed, not asserted)");
  auto brec = std::make_shared<record::BenchRecordOptions>();
  CLI::App* bench_record = bench->add_subcommand(
      "record", "Recorder throughput: MCAP writer alone, then DDS -> recorder at rising rates "
                "(best-effort ImuSample, loopback) until messages are lost.");
  bench_record->add_option("--duration", brec->seconds_per_step, "how long each rate step runs, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  add_deprecated_alias(bench_record, "--seconds", "--duration", &brec->seconds_per_step)->check(CLI::PositiveNumber);
  add_dds_profile_option(bench_record, &brec->profile)->capture_default_str();
  add_deprecated_alias(bench_record, "--profile", "--dds-profile", &brec->profile);
  add_domain_option(bench_record, &brec->domain);
  bench_record->callback([brec] {
    try {
      record::bench_record(*brec, std::cout);
    } catch (const dds::DdsError& e) {
      throw Error(e.what());
    }
  });
  auto brep = std::make_shared<record::BenchReplayOptions>();
  CLI::App* bench_replay = bench->add_subcommand(
      "replay", "Replay speed as a multiple of real time for a 1 kHz IMU recording (reader "
                "alone, then over DDS as fast as possible).");
  bench_replay->add_option("--duration", brep->recording_s, "length of the recording, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  add_deprecated_alias(bench_replay, "--seconds", "--duration", &brep->recording_s)->check(CLI::PositiveNumber);
  add_dds_profile_option(bench_replay, &brep->profile)->capture_default_str();
  add_deprecated_alias(bench_replay, "--profile", "--dds-profile", &brep->profile);
  add_domain_option(bench_replay, &brep->domain);
  bench_replay->callback([brep] {
    try {
      record::bench_replay(*brep, std::cout);
    } catch (const dds::DdsError& e) {
      throw Error(e.what());
    }
  });
}

}  // namespace poise::cli
