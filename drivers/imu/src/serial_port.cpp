#include "poise/imu/serial_port.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/file.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <memory>
#include <cstring>
#include <ctime>
#include <thread>

namespace poise::imu {
namespace {

constexpr unsigned kPtySlaveMajorFirst = 136;  // UNIX98_PTY_SLAVE_MAJOR .. +7
constexpr unsigned kPtySlaveMajorLast = 143;

bool baud_constant(int baud, speed_t* out) {
  switch (baud) {
    case 9600: *out = B9600; return true;
    case 19200: *out = B19200; return true;
    case 38400: *out = B38400; return true;
    case 57600: *out = B57600; return true;
    case 115200: *out = B115200; return true;
    case 230400: *out = B230400; return true;
    case 460800: *out = B460800; return true;
    case 500000: *out = B500000; return true;
    case 576000: *out = B576000; return true;
    case 921600: *out = B921600; return true;
    case 1000000: *out = B1000000; return true;
    default: return false;
  }
}

std::string open_hint(const std::string& path, int err) {
  switch (err) {
    case ENOENT:
      return path + " does not exist (is the board plugged in? list ports with "
                    "`ls /dev/ttyUSB* /dev/ttyACM*`, or start `poise sim-imu --link " + path + "`)";
    case EACCES:
    case EPERM:
      return "permission denied on " + path +
             " (add yourself to the dialout group: `sudo usermod -aG dialout $USER`, then log in "
             "again)";
    case EBUSY:
      return path + " is in use by another process (close the serial monitor or the other "
                    "`poise imu`)";
    default:
      return path + ": " + std::strerror(err);
  }
}

}  // namespace

int64_t monotonic_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

SerialPort::SerialPort(const std::string& path, int baud) {
  speed_t speed = B0;
  if (!baud_constant(baud, &speed)) {
    throw SerialError("baud rate " + std::to_string(baud) +
                          " is not supported (use 9600, 19200, 38400, 57600, 115200, 230400, "
                          "460800, 500000, 576000, 921600 or 1000000)",
                      EINVAL);
  }
  fd_ = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) {
    const int err = errno;
    throw SerialError(open_hint(path, err), err);
  }
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    close_fd();
    throw SerialError(open_hint(path, err == EWOULDBLOCK ? EBUSY : err), EBUSY);
  }
  termios tio{};
  if (::tcgetattr(fd_, &tio) != 0) {
    const int err = errno;
    close_fd();
    throw SerialError(path + " is not a serial device (tcgetattr: " + std::strerror(err) + ")", err);
  }
  if (::ioctl(fd_, TIOCEXCL) != 0) {
    const int err = errno;
    close_fd();
    throw SerialError(path + ": cannot get exclusive access (" + std::strerror(err) + ")", err);
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~static_cast<tcflag_t>(CSTOPB | PARENB | CRTSCTS);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  ::cfsetispeed(&tio, speed);
  ::cfsetospeed(&tio, speed);
  if (::tcsetattr(fd_, TCSANOW, &tio) != 0) {
    const int err = errno;
    close_fd();
    throw SerialError(path + ": cannot configure " + std::to_string(baud) + " baud raw mode (" +
                          std::strerror(err) + ")",
                      err);
  }
  ::tcflush(fd_, TCIFLUSH);  // drop whatever queued before we were listening
  struct stat st {};
  if (::fstat(fd_, &st) == 0 && S_ISCHR(st.st_mode)) {
    const unsigned maj = major(st.st_rdev);
    is_pty_ = maj >= kPtySlaveMajorFirst && maj <= kPtySlaveMajorLast;
  }
}

SerialPort::~SerialPort() { close_fd(); }

SerialPort::SerialPort(SerialPort&& other) noexcept : fd_(other.fd_), is_pty_(other.is_pty_) {
  other.fd_ = -1;
}

SerialPort& SerialPort::operator=(SerialPort&& other) noexcept {
  if (this != &other) {
    close_fd();
    fd_ = other.fd_;
    is_pty_ = other.is_pty_;
    other.fd_ = -1;
  }
  return *this;
}

void SerialPort::close_fd() {
  if (fd_ >= 0) {
    ::close(fd_);  // releases the flock too
    fd_ = -1;
  }
}

SerialPort::ReadStatus SerialPort::read(char* buf, std::size_t cap, int timeout_ms, std::size_t* n,
                                        std::string* why) {
  *n = 0;
  pollfd p{fd_, POLLIN, 0};
  const int r = ::poll(&p, 1, timeout_ms);
  if (r < 0) {
    if (errno == EINTR) return ReadStatus::kTimeout;
    *why = std::string("poll: ") + std::strerror(errno);
    return ReadStatus::kLost;
  }
  if (r == 0) return ReadStatus::kTimeout;
  if ((p.revents & POLLNVAL) != 0) {
    *why = "port closed (POLLNVAL)";
    return ReadStatus::kLost;
  }
  // Read even when HUP is flagged: bytes queued before the hangup are still delivered.
  const ssize_t got = ::read(fd_, buf, cap);
  if (got > 0) {
    *n = static_cast<std::size_t>(got);
    return ReadStatus::kData;
  }
  if (got == 0) {
    *why = "hangup (device closed or unplugged)";
    return ReadStatus::kLost;
  }
  const int err = errno;
  if (err == EAGAIN || err == EINTR) {
    if ((p.revents & (POLLHUP | POLLERR)) != 0) {
      *why = "hangup (POLLHUP)";
      return ReadStatus::kLost;
    }
    return ReadStatus::kTimeout;
  }
  *why = std::string(err == EIO ? "EIO" : err == ENXIO ? "ENXIO" : err == ENODEV ? "ENODEV" : "read") +
         ": " + std::strerror(err);
  return ReadStatus::kLost;
}

void check_serial_path(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || S_ISCHR(st.st_mode)) {
    return;  // absent (may appear) or a character device
  }
  const char* what = S_ISDIR(st.st_mode) ? "a directory" : S_ISREG(st.st_mode) ? "a regular file" : "not a device";
  throw SerialError(path + " is " + what + ", not a serial device (pass the port, e.g. /dev/ttyUSB0, or the "
                           "link of `poise sim-imu --link PATH`)",
                    ENOTTY);
}

PortReader::PortReader(ReaderOptions options, ImuDriver& driver, Log log)
    : options_(std::move(options)), driver_(driver), log_(std::move(log)) {
  check_serial_path(options_.path);
}

void PortReader::run(const std::function<bool()>& stop, const std::function<void(int64_t)>& on_tick) {
  double backoff_s = options_.serial.reconnect_initial_s;
  std::string last_error;
  int64_t next_attempt_ns = 0;
  char buf[4096];
  const auto tick = [&](int64_t now) {
    if (on_tick) on_tick(now);
  };
  while (!stop()) {
    const int64_t now = monotonic_now_ns();
    if (now < next_attempt_ns) {
      const auto wait_ns = std::min<int64_t>(next_attempt_ns - now, int64_t{options_.poll_ms} * 1000000);
      std::this_thread::sleep_for(std::chrono::nanoseconds(wait_ns));
      tick(monotonic_now_ns());
      continue;
    }
    std::unique_ptr<SerialPort> port;
    try {
      port = std::make_unique<SerialPort>(options_.path, options_.serial.baud);
    } catch (const SerialError& e) {
      try {
        check_serial_path(options_.path);
      } catch (const SerialError& fatal) {
        log_(std::string(fatal.what()) + ": giving up");
        gave_up_.store(true);
        return;
      }
      if (e.what() != last_error) {
        log_(std::string("waiting for ") + options_.path + ": " + e.what() + "; retrying");
        last_error = e.what();
      }
      next_attempt_ns = monotonic_now_ns() + static_cast<int64_t>(backoff_s * 1e9);
      backoff_s = std::min(backoff_s * 2.0, options_.serial.reconnect_max_s);
      tick(monotonic_now_ns());
      continue;
    }
    const bool correct_tx = options_.serial.tx_correction == "on" ||
                            (options_.serial.tx_correction == "auto" && !port->is_pty());
    driver_.set_link_bytes_per_s(correct_tx ? options_.serial.baud / 10.0 : 0.0);
    connected_.store(true);
    connects_.fetch_add(1);
    last_error.clear();
    backoff_s = options_.serial.reconnect_initial_s;
    log_(std::string("connected to ") + options_.path + " at " + std::to_string(options_.serial.baud) +
         " baud" + (port->is_pty() ? " (pseudo-terminal)" : ""));
    while (!stop()) {
      std::size_t n = 0;
      std::string why;
      const auto st = port->read(buf, sizeof buf, options_.poll_ms, &n, &why);
      const int64_t arrival = monotonic_now_ns();
      if (st == SerialPort::ReadStatus::kData) {
        driver_.feed(buf, n, arrival);
      } else if (st == SerialPort::ReadStatus::kLost) {
        log_(options_.path + " lost (" + why + "); reconnecting");
        break;
      }
      tick(arrival);
    }
    port.reset();
    connected_.store(false);
    if (!stop()) {
      driver_.reset();
      next_attempt_ns = monotonic_now_ns() + static_cast<int64_t>(backoff_s * 1e9);
    }
  }
}

}  // namespace poise::imu
