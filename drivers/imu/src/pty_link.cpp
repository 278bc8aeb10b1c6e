#include "poise/imu/pty_link.h"

#include <algorithm>

#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstring>
#include <stdexcept>

namespace poise::imu {

PtyLink::PtyLink(std::string link_path) : link_(std::move(link_path)) {
  struct stat st {};
  if (::lstat(link_.c_str(), &st) == 0 && !S_ISLNK(st.st_mode)) {
    throw std::runtime_error(link_ + " exists and is not a symlink; choose another --link path");
  }
  open_pty();
}

PtyLink::~PtyLink() { disconnect(); }

void PtyLink::open_pty() {
  int master = -1;
  int slave = -1;
  char name[PATH_MAX] = {};
  termios tio{};
  ::cfmakeraw(&tio);
  if (::openpty(&master, &slave, name, &tio, nullptr) != 0) {
    throw std::runtime_error(std::string("openpty failed: ") + std::strerror(errno) +
                             " (is /dev/ptmx available?)");
  }
  ::close(slave);  // readers open it through the symlink; HUP on the master means "no reader"
  ::fcntl(master, F_SETFL, ::fcntl(master, F_GETFL) | O_NONBLOCK);
  ::fcntl(master, F_SETFD, FD_CLOEXEC);
  master_ = master;
  slave_name_ = name;
  had_reader_ = false;
  const std::string tmp = link_ + ".tmp" + std::to_string(::getpid());
  ::unlink(tmp.c_str());
  if (::symlink(slave_name_.c_str(), tmp.c_str()) != 0 || ::rename(tmp.c_str(), link_.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    ::close(master_);
    master_ = -1;
    throw std::runtime_error("cannot create symlink " + link_ + " -> " + slave_name_ + ": " +
                             std::strerror(err) + " (check the directory exists and is writable)");
  }
}

void PtyLink::remove_link() {
  char target[PATH_MAX] = {};
  const ssize_t n = ::readlink(link_.c_str(), target, sizeof target - 1);
  if (n > 0 && std::string(target, static_cast<std::size_t>(n)) == slave_name_) {
    ::unlink(link_.c_str());  // only our own link: never remove someone else's
  }
}

void PtyLink::disconnect() {
  if (master_ < 0) return;
  remove_link();
  ::close(master_);
  master_ = -1;
}

void PtyLink::reconnect() {
  disconnect();
  open_pty();
}

bool PtyLink::has_reader() const {
  if (master_ < 0) return false;
  pollfd p{master_, POLLOUT, 0};
  ::poll(&p, 1, 0);
  return (p.revents & POLLHUP) == 0;
}

PtyLink::WriteStatus PtyLink::write(std::string_view data, int full_wait_ms) {
  if (master_ < 0) return WriteStatus::kDisconnected;
  pollfd p{master_, POLLOUT, 0};
  ::poll(&p, 1, had_reader_ ? std::max(0, full_wait_ms) : 0);
  if ((p.revents & POLLHUP) != 0) {
    had_reader_ = false;
    return WriteStatus::kNoReader;
  }
  if (!had_reader_) {
    ::tcflush(master_, TCIOFLUSH);  // a new reader starts with a clean line
    had_reader_ = true;
  }
  if ((p.revents & POLLOUT) == 0) return WriteStatus::kFull;
  ssize_t n = ::write(master_, data.data(), data.size());
  if (n < 0) {
    if (errno == EAGAIN || errno == EWOULDBLOCK) return WriteStatus::kFull;
    return WriteStatus::kNoReader;
  }
  // A line is never left half-written if the reader drains within a short bound: finish it.
  std::size_t done = static_cast<std::size_t>(n);
  constexpr int kFinishTimeoutMs = 1000;
  while (done < data.size()) {
    pollfd q{master_, POLLOUT, 0};
    if (::poll(&q, 1, kFinishTimeoutMs) <= 0 || (q.revents & POLLHUP) != 0) {
      return WriteStatus::kFull;  // cut line on the wire: the reader counts it as truncated
    }
    n = ::write(master_, data.data() + done, data.size() - done);
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) return WriteStatus::kNoReader;
    if (n > 0) done += static_cast<std::size_t>(n);
  }
  return WriteStatus::kWritten;
}

}  // namespace poise::imu
