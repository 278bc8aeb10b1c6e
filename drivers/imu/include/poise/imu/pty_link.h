// A pseudo-terminal exposed at a symlink path: the device side of `poise sim-imu` and of tests.
#pragma once

#include <string>
#include <string_view>

namespace poise::imu {

/// How long a simulated board (`poise sim-imu`, the sim_imu component) waits for a reader that
/// has the port open but no room, before it drops the line (counted): a reader stalled longer
/// than this loses lines, as on a real UART.
inline constexpr int kSimulatedBoardWaitMs = 1000;

/// Owns a pty master in raw mode and a symlink PATH -> /dev/pts/N. The symlink is removed on
/// destruction and on disconnect(); reconnect() opens a new pty at the same PATH (like a board
/// unplugged and plugged back). Never replaces PATH if it exists and is not a symlink.
class PtyLink {
 public:
  explicit PtyLink(std::string link_path);  ///< throws std::runtime_error with what to do
  ~PtyLink();
  PtyLink(const PtyLink&) = delete;
  PtyLink& operator=(const PtyLink&) = delete;

  enum class WriteStatus { kWritten, kNoReader, kFull, kDisconnected };
  /// Writes `data` entirely or not at all. kNoReader: nobody has the port open (the bytes are
  /// dropped, as on a real UART); kFull: the reader has not made room within `full_wait_ms`
  /// (dropped; if the reader stalls for 1 s mid-line, the line stays cut and the reader counts it
  /// as truncated). A simulated board passes a wait: a burst after the simulator's own stall (a
  /// loaded host) is not a real board's, which sends at its steady pace, and must not cost lines.
  WriteStatus write(std::string_view data, int full_wait_ms = 0);
  /// True while some process has the device open (no hangup on the master).
  [[nodiscard]] bool has_reader() const;
  void disconnect();
  void reconnect();  ///< throws std::runtime_error
  [[nodiscard]] bool connected() const { return master_ >= 0; }
  [[nodiscard]] const std::string& slave_name() const { return slave_name_; }
  [[nodiscard]] const std::string& link_path() const { return link_; }

 private:
  void open_pty();
  void remove_link();
  std::string link_;
  std::string slave_name_;
  int master_ = -1;
  bool had_reader_ = false;
};

}  // namespace poise::imu
