// Byte stream -> protocol lines. Robust to garbage, partial reads, missing terminators and
// arbitrarily long noise; memory is bounded by kMaxLineBytes. Pure: no I/O.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "poise/imu/protocol.h"

namespace poise::imu {

/// Receives the framer's events. Lines are passed without their terminator.
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  /// A complete candidate line starting with '$' (may still be invalid).
  virtual void on_line(std::string_view line) = 0;
  /// A firmware message line starting with '#' (e.g. "# gy87_poise v1 ready").
  virtual void on_info(std::string_view text) = 0;
  /// Bytes that could not become a line: kGarbage, kOverlong or kTruncated. `bytes` is the size of
  /// the discarded run (as far as it was seen).
  virtual void on_reject(RejectReason reason, std::size_t bytes) = 0;
};

/// Splits a byte stream into lines: a line starts at '$' and ends at '\n' ("\r\n" accepted).
///  - bytes outside a '$' line form a text run; at '\n' it is an info message if it starts with
///    '#', ignored if it is blank, else one kGarbage event (also on a '$' that interrupts it);
///  - a '$' inside an unterminated line ends that line as kTruncated;
///  - a line longer than kMaxLineBytes is kOverlong and skipped up to the next '$' or '\n'.
class LineFramer {
 public:
  LineFramer();
  void feed(const char* data, std::size_t size, FrameSink& sink);
  /// The stream broke (disconnect): a line in progress is reported as kTruncated and dropped.
  void reset(FrameSink& sink);

 private:
  enum class Mode { kText, kLine, kDiscard };
  void end_text(FrameSink& sink);
  Mode mode_ = Mode::kText;
  std::string line_;
  std::string text_;          // start of the current non-'$' run (bounded)
  std::size_t text_bytes_ = 0;  // full length of the current non-'$' run
  std::size_t discard_bytes_ = 0;
};

}  // namespace poise::imu
