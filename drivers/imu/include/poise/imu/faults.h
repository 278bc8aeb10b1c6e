// Fault injection for `poise sim-imu` and tests (pure; seeded).
//
// SPEC: comma-separated KEY=VALUE items, e.g. "garbage=0.01,flip=0.002,disconnect=5:0.5,seed=3"
//   garbage=P   insert 1..32 noise bytes (no '$' or '\n') before a line  -> 1 garbage
//   drop=P      the line is not sent                                       -> 1 seq-gap drop
//   flip=P      one bit flipped in the payload (between '$' and '*')       -> 1 checksum_mismatch
//   truncate=P  the line loses its tail (the "\r\n" still follows)        -> 1 truncated
//   dup=P       the line is sent twice                                     -> 1 duplicate_seq
//   swap=P      the line is sent after the next one                        -> 1 out_of_order_seq
//   nan=P       the first accelerometer field becomes "nan" (valid CS)     -> 1 not_finite
//   disconnect=EVERY:DOWN   every EVERY s the device vanishes for DOWN s (sim-imu)
//   seed=N      random seed (default 1)
// P is a per-line probability in [0, 1]; at most one fault is applied to a line, so the driver's
// reject counters equal the injector's counters (the driver also counts every line not published
// by a fault, except garbage and dup, as a sequence-gap drop).
#pragma once

#include <array>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace poise::imu {

enum class Fault : int { kGarbage = 0, kDrop, kFlip, kTruncate, kDup, kSwap, kNan, kCount };
inline constexpr std::size_t kFaultCount = static_cast<std::size_t>(Fault::kCount);
const char* to_string(Fault f);

struct FaultSpec {
  std::array<double, kFaultCount> probability{};  ///< per line
  double disconnect_every_s = 0;                  ///< 0 = never
  double disconnect_down_s = 0;
  uint32_t seed = 1;
  /// Parses SPEC (see the header comment); "" or "none" = no faults. Throws std::invalid_argument
  /// with a message naming the bad item.
  static FaultSpec parse(const std::string& spec);
  [[nodiscard]] bool any_line_faults() const;
};

class FaultInjector {
 public:
  explicit FaultInjector(const FaultSpec& spec);
  /// Transforms one complete line ("$...*CS\r\n") into the bytes to send now (possibly none, or
  /// more than one line when a swapped line is released).
  std::string apply(const std::string& line);
  /// Bytes held back by a pending swap (send them before a disconnect or at the end).
  std::string flush();
  [[nodiscard]] const std::array<uint64_t, kFaultCount>& counts() const { return counts_; }

 private:
  FaultSpec spec_;
  std::mt19937 rng_;
  std::string held_;
  std::array<uint64_t, kFaultCount> counts_{};
};

}  // namespace poise::imu
