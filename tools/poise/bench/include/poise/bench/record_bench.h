// `poise bench record` and `poise bench replay`: figures, no assertions.
#pragma once

#include <ostream>
#include <string>

namespace poise::record {

struct BenchRecordOptions {
  double seconds_per_step = 2.0;
  int domain = 0;
  std::string profile = "poise_loopback";
};

struct BenchReplayOptions {
  double recording_s = 60.0;
  int domain = 0;
  std::string profile = "poise_loopback";
};

void bench_record(const BenchRecordOptions& options, std::ostream& out);
void bench_replay(const BenchReplayOptions& options, std::ostream& out);

}  // namespace poise::record
