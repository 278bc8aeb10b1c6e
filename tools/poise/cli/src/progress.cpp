#include "poise/cli/progress.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <utility>

namespace poise::cli {

Progress::Progress(std::string what, uint64_t total) : Progress(std::move(what), total, Options{}) {}

Progress::Progress(std::string what, uint64_t total, Options options)
    : what_(std::move(what)), total_(total), options_(std::move(options)) {
  if (options_.out == nullptr) {
    options_.out = &std::cerr;
  }
  if (options_.terminal < 0) {
    options_.terminal = ::isatty(STDERR_FILENO) != 0 ? 1 : 0;
  }
  if (!options_.now_s) {
    options_.now_s = [] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
    };
  }
  start_s_ = options_.now_s();
  if (options_.ticker) {
    ticker_ = std::thread([this] {
      std::unique_lock<std::mutex> lock(mutex_);
      while (!finished_) {
        wake_.wait_for(lock, std::chrono::duration<double>(kProgressRedrawS));
        if (!finished_) {
          show(options_.now_s());
        }
      }
    });
  }
}

Progress::~Progress() { finish(); }

std::string Progress::line(uint64_t done, const std::string& detail, double elapsed_s) const {
  char buf[128];
  if (total_ > 0) {
    const double pct = 100.0 * static_cast<double>(std::min(done, total_)) / static_cast<double>(total_);
    if (options_.counts) {
      std::snprintf(buf, sizeof buf, ": %3.0f %% (%llu/%llu), %.0f s", pct, static_cast<unsigned long long>(done),
                    static_cast<unsigned long long>(total_), elapsed_s);
    } else {
      std::snprintf(buf, sizeof buf, ": %3.0f %%, %.0f s", pct, elapsed_s);
    }
  } else {
    std::snprintf(buf, sizeof buf, ": %llu, %.0f s", static_cast<unsigned long long>(done), elapsed_s);
  }
  return what_ + buf + (detail.empty() ? "" : ", " + detail);
}

void Progress::update(uint64_t done, const std::string& detail) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) {
    return;
  }
  done_ = done;
  detail_ = detail;
  show(options_.now_s());
}

void Progress::show(double now) {
  const uint64_t done = done_;
  const std::string& detail = detail_;
  const double elapsed = now - start_s_;
  if (elapsed < kProgressQuietS) {
    return;
  }
  const double every = options_.terminal == 1 ? kProgressRedrawS : kProgressLineEveryS;
  if (last_shown_s_ >= 0.0 && now - last_shown_s_ < every) {
    return;
  }
  last_shown_s_ = now;
  const std::string text = line(done, detail, elapsed);
  std::ostream& os = *options_.out;
  if (options_.terminal == 1) {
    os << "\r" << text;
    if (text.size() < last_width_) {
      os << std::string(last_width_ - text.size(), ' ');  // wipe the longer previous line
    }
    last_width_ = text.size();
  } else {
    os << text << "\n";
  }
  os.flush();
}

void Progress::hide() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (options_.terminal == 1 && last_width_ > 0) {
    *options_.out << "\r" << std::string(last_width_, ' ') << "\r";
    options_.out->flush();
    last_width_ = 0;
    last_shown_s_ = last_shown_s_ >= 0.0 ? last_shown_s_ - kProgressRedrawS : last_shown_s_;  // redraw soon
  }
}

void Progress::note(const std::string& text) {
  hide();
  std::lock_guard<std::mutex> lock(mutex_);
  *options_.out << text << "\n";
  options_.out->flush();
}

void Progress::finish() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_) {
      return;
    }
    finished_ = true;
  }
  wake_.notify_all();
  if (ticker_.joinable()) {
    ticker_.join();
  }
  if (last_shown_s_ < 0.0) {
    return;  // short work: nothing was shown, nothing to close
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, ": done in %.1f s", options_.now_s() - start_s_);
  const std::string text = what_ + buf;
  std::ostream& os = *options_.out;
  if (options_.terminal == 1) {
    os << "\r" << text;
    if (text.size() < last_width_) {
      os << std::string(last_width_ - text.size(), ' ');
    }
  }
  os << (options_.terminal == 1 ? "\n" : text + "\n");
  os.flush();
}

}  // namespace poise::cli
