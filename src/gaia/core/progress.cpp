#include "gaia/core/progress.h"

#include <unistd.h>

#include <cstdio>
#include <exception>

#include <fmt/format.h>

namespace gaia {

ProgressBar::ProgressBar(int64_t total, std::string label, bool enabled, int64_t start)
    : total_(total), start_done_(start), done_(start), label_(std::move(label)), enabled_(enabled),
      tty_(::isatty(STDERR_FILENO) != 0) {
  start_ = last_draw_ = std::chrono::steady_clock::now();
}

ProgressBar::~ProgressBar() {
  if (finished_ || !enabled_ || done_ <= start_done_) return;
  // Unwound by an error: end the bar's line so the error line that follows stands alone, without a "done" line.
  if (std::uncaught_exceptions() > 0) {
    if (tty_) std::fputs("\n", stderr);
    return;
  }
  finish();
}

std::string ProgressBar::format_duration(double s) {
  if (!(s >= 0) || s > 1e7) return "?";
  if (s < 60) return fmt::format("{:.1f}s", s);
  int64_t t = static_cast<int64_t>(s + 0.5);
  if (t < 3600) return fmt::format("{}m{:02d}s", t / 60, t % 60);
  return fmt::format("{}h{:02d}m", t / 3600, (t % 3600) / 60);
}

void ProgressBar::update(int64_t done, const std::string& info) {
  done_ = done;
  info_ = info;
  if (!enabled_) return;
  auto now = std::chrono::steady_clock::now();
  if (tty_) {
    if (now - last_draw_ < std::chrono::milliseconds(100) && done < total_) return;
    last_draw_ = now;
    draw(false);
  } else {
    // Logs: a line every 10% or every 30 s, whichever comes first.
    int decile = total_ > 0 ? static_cast<int>(10 * done / total_) : 0;
    if (decile != last_decile_ || now - last_draw_ > std::chrono::seconds(30)) {
      last_decile_ = decile;
      last_draw_ = now;
      draw(false);
    }
  }
}

void ProgressBar::finish(const std::string& info) {
  if (!info.empty()) info_ = info;
  if (total_ > 0 && done_ < total_) done_ = done_ > 0 ? done_ : total_;
  if (enabled_) draw(true);
  finished_ = true;
}

void ProgressBar::draw(bool final) {
  double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  double frac = total_ > 0 ? static_cast<double>(done_) / static_cast<double>(total_) : 0.0;
  double rate = elapsed > 0 ? static_cast<double>(done_ - start_done_) / elapsed : 0.0;
  double eta = rate > 0 ? static_cast<double>(total_ - done_) / rate : -1;
  constexpr int kWidth = 24;
  int filled = static_cast<int>(frac * kWidth);
  std::string bar = std::string(static_cast<size_t>(filled), '#') + std::string(static_cast<size_t>(kWidth - filled), '.');
  std::string line = fmt::format("{} [{}] {}/{} {:3.0f}% {:.1f}/s elapsed {} {} {}", label_, bar, done_, total_,
                                 100 * frac, rate, format_duration(elapsed),
                                 final ? "" : "ETA " + format_duration(eta), info_);
  if (tty_) std::fprintf(stderr, "\r\033[K%s%s", line.c_str(), final ? "\n" : "");
  else std::fprintf(stderr, "%s\n", line.c_str());
  std::fflush(stderr);
}

}  // namespace gaia
