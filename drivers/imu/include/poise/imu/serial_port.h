// POSIX serial port (termios raw 8N1, exclusive) and the reconnecting reader loop.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>

#include "poise/imu/driver.h"

namespace poise::imu {

/// Opening or configuring a port failed; what() says what to do.
class SerialError : public std::runtime_error {
 public:
  SerialError(const std::string& message, int err) : std::runtime_error(message), errno_(err) {}
  [[nodiscard]] int error_number() const { return errno_; }

 private:
  int errno_;
};

/// Host CLOCK_MONOTONIC in ns (the I/O layer's only clock; the driver core takes time as input).
int64_t monotonic_now_ns();

/// An open serial device in raw mode: 8 data bits, no parity, 1 stop bit, no flow control,
/// non-blocking, exclusive (flock + TIOCEXCL). Move-only RAII.
class SerialPort {
 public:
  /// Throws SerialError (missing device, permission, busy, not a tty, unsupported baud).
  SerialPort(const std::string& path, int baud);
  ~SerialPort();
  SerialPort(SerialPort&& other) noexcept;
  SerialPort& operator=(SerialPort&& other) noexcept;
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;

  [[nodiscard]] int fd() const { return fd_; }
  /// True for a pseudo-terminal (e.g. `poise sim-imu`): no baud-rate transmission delay.
  [[nodiscard]] bool is_pty() const { return is_pty_; }

  enum class ReadStatus { kData, kTimeout, kLost };
  /// Waits up to `timeout_ms` for bytes and reads what is there. kLost on EIO/ENXIO/ENODEV/HUP
  /// (device unplugged); `why` then says what happened.
  ReadStatus read(char* buf, std::size_t cap, int timeout_ms, std::size_t* n, std::string* why);

 private:
  void close_fd();
  int fd_ = -1;
  bool is_pty_ = false;
};

/// The serial section of the driver configuration (config/drivers/imu.yaml `serial:`). The
/// defaults live here only.
struct SerialSettings {
  int baud = 115200;                ///< one of supported_bauds()
  double reconnect_initial_s = 0.1; ///< first retry delay after a lost/absent port, s
  double reconnect_max_s = 2.0;     ///< retry delay cap (doubles each failure), s
  /// Correct arrival times by each line's transmission time at `baud`: "auto" (yes for real UARTs,
  /// no for pseudo-terminals), "on", "off".
  std::string tx_correction = "auto";
};

struct ReaderOptions {
  std::string path;
  SerialSettings serial;  ///< baud, reconnect delays, transmission-time correction
  int poll_ms = 50;       ///< longest wait between on_tick calls, ms
};

/// Throws SerialError when `path` exists and is not a character device (a regular file, a
/// directory, a FIFO, a socket): that never becomes a serial port, so retrying is pointless. A
/// path that does not exist yet passes (the board may be plugged in later).
void check_serial_path(const std::string& path);

/// Reads a port forever, feeding the driver; survives unplug/replug: on loss it resets the driver
/// and retries opening with exponential backoff, resuming without restart. Single-threaded: the
/// driver's sink and on_tick run on the calling thread.
class PortReader {
 public:
  using Log = std::function<void(const std::string&)>;
  /// Throws SerialError when the path can never be a serial port (check_serial_path()).
  PortReader(ReaderOptions options, ImuDriver& driver, Log log);
  /// Runs until `stop()` is true, or until the path turns into something that is not a
  /// character device (logged once; gave_up() is then true). `on_tick(now_ns)` is called at
  /// least every poll_ms.
  void run(const std::function<bool()>& stop, const std::function<void(int64_t)>& on_tick = {});
  [[nodiscard]] bool connected() const { return connected_.load(); }
  [[nodiscard]] uint64_t connects() const { return connects_.load(); }
  [[nodiscard]] bool gave_up() const { return gave_up_.load(); }

 private:
  ReaderOptions options_;
  ImuDriver& driver_;
  Log log_;
  std::atomic<bool> connected_{false};
  std::atomic<uint64_t> connects_{0};
  std::atomic<bool> gave_up_{false};
};

}  // namespace poise::imu
