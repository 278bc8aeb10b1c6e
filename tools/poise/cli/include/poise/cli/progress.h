// Progress of long work on stderr, the same in every command (docs/TOOLS.md "Progress"):
// nothing for work that ends within kProgressQuietS; past that, one line redrawn in place on a
// terminal, or a few plain lines (one every kProgressLineEveryS) when stderr is a file or a pipe.
#pragma once

#include <cstdint>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>
#include <ostream>
#include <string>

namespace poise::cli {

/// Work shorter than this prints no progress at all, s.
inline constexpr double kProgressQuietS = 2.0;
/// On a terminal the line is redrawn at most this often, s.
inline constexpr double kProgressRedrawS = 0.2;
/// Not on a terminal: at most one line this often, s.
inline constexpr double kProgressLineEveryS = 10.0;

class Progress {
 public:
  struct Options {
    std::ostream* out = nullptr;               ///< default: std::cerr
    int terminal = -1;                         ///< 1 / 0: a terminal or not; -1: isatty(stderr)
    std::function<double()> now_s;             ///< monotonic seconds; default: steady_clock
    bool counts = true;                        ///< show "(done/total)" after the percentage
    /// A thread redraws the last state every kProgressRedrawS, so one long step (a trial that
    /// takes 10 s) still shows time passing. Off in tests with an injected clock.
    bool ticker = true;
  };
  /// `what` names the work ("poise process"); `total` units of it (0: unknown).
  Progress(std::string what, uint64_t total);
  Progress(std::string what, uint64_t total, Options options);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// `done` of `total` units so far; `detail` says where (e.g. the file). Cheap when nothing is due.
  void update(uint64_t done, const std::string& detail = {});
  /// Before printing anything else on a terminal: wipes the line (redrawn by the next update()).
  void hide();
  /// A message between progress updates (stderr): on its own line, whatever the display.
  void note(const std::string& text);
  /// Ends the display: a terminal's line is completed ("... done in 12.3 s"); nothing when
  /// nothing was shown. Called by the destructor.
  void finish();

 private:
  void show(double now);  // with mutex_ held
  std::string line(uint64_t done, const std::string& detail, double elapsed_s) const;

  std::string what_;
  uint64_t total_;
  Options options_;
  double start_s_ = 0.0;
  double last_shown_s_ = -1.0;  ///< < 0: nothing shown yet
  std::size_t last_width_ = 0;
  bool finished_ = false;
  uint64_t done_ = 0;
  std::string detail_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread ticker_;
};

}  // namespace poise::cli
