#pragma once
// Progress bar with rate and ETA for anything that runs longer than a few seconds. Writes to stderr (never
// stdout, which carries results); on a terminal it redraws one line, otherwise it prints a line every ~10%.
#include <chrono>
#include <cstdint>
#include <string>

namespace gaia {

class ProgressBar {
 public:
  // `start` is where a resumed run picks up: rate and ETA count only the work done since then.
  ProgressBar(int64_t total, std::string label, bool enabled = true, int64_t start = 0);
  ~ProgressBar();
  void update(int64_t done, const std::string& info = "");  // cheap; redraws at most ~10 times a second
  void finish(const std::string& info = "");
  static std::string format_duration(double seconds);  // "1h02m", "3m05s", "12.3s"

 private:
  void draw(bool final);
  int64_t total_, start_done_, done_;
  std::string label_, info_;
  bool enabled_, tty_, finished_ = false;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point start_, last_draw_;
};

}  // namespace gaia
