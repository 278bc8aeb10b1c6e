// Fuzz target for the serial IMU parser and driver core (libFuzzer entry point; also driven by
// the GoogleTest replay in fuzz_replay_test.cpp when libFuzzer is unavailable).
// Invariants checked (abort on violation): no crash/UB; an accepted line has finite values within
// the limits and re-formats to an accepted line with the same seq; the driver's samples are
// finite with strictly increasing stamps, and its counters are consistent.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "poise/imu/driver.h"
#include "poise/imu/protocol.h"

namespace {

void check(bool ok) {
  if (!ok) std::abort();
}

void check_sample_values(const poise::imu::RawSample& s, const poise::imu::Limits& l) {
  check(s.accel_mps2.allFinite() && s.gyro_rps.allFinite() && s.mag_ut.allFinite());
  check(s.accel_mps2.cwiseAbs().maxCoeff() <= l.accel_max_mps2);
  check(s.gyro_rps.cwiseAbs().maxCoeff() <= l.gyro_max_rps);
  check(s.mag_ut.cwiseAbs().maxCoeff() <= l.mag_max_ut);
  if (s.has_pressure) {
    check(std::isfinite(s.pressure_pa) && s.pressure_pa >= l.pressure_min_pa &&
          s.pressure_pa <= l.pressure_max_pa);
  }
  if (s.has_temperature) check(std::isfinite(s.temperature_c));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);

  // 1. The line parser on the whole input as one line.
  const poise::imu::LineParser parser;
  const poise::imu::ParseResult r = parser.parse(text);
  if (r.ok) {
    check_sample_values(r.sample, parser.limits());
    if (!r.sample.from_raw_counts) {
      std::string again = poise::imu::format_imu_line(r.sample, 9);
      again.resize(again.size() - 2);
      const poise::imu::ParseResult r2 = parser.parse(again);
      check(r2.ok && r2.sample.seq == r.sample.seq && r2.sample.t_us == r.sample.t_us);
    }
  } else {
    check(r.reason < poise::imu::RejectReason::kCount);
  }

  // 2. The driver on the input as a byte stream, split into chunks chosen by the input itself.
  uint64_t delivered = 0;
  int64_t last_stamp = INT64_MIN;
  poise::imu::ImuDriver driver({}, {}, [&](const poise::ImuSample& s, const poise::imu::SampleInfo& i) {
    check(s.accel_mps2.allFinite() && s.gyro_rps.allFinite() && s.mag_ut.allFinite());
    check(s.stamp_ns > last_stamp);
    last_stamp = s.stamp_ns;
    check_sample_values(i.raw, poise::imu::Limits{});
    ++delivered;
  });
  int64_t now = 1'000'000'000;
  std::size_t i = 0;
  while (i < size) {
    const std::size_t chunk = 1 + static_cast<std::size_t>(data[i] % 61);
    const std::size_t n = chunk < size - i ? chunk : size - i;
    now += static_cast<int64_t>(data[i]) * 1000;
    driver.feed(text.substr(i, n), now);
    i += n;
  }
  driver.reset();
  const auto& st = driver.stats();
  check(st.samples == delivered);
  check(st.lines >= st.samples);
  check(st.bytes == size);
  return 0;
}
