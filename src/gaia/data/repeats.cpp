#include "gaia/data/repeats.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "gaia/core/error.h"

namespace gaia::data {

namespace {
constexpr int kThumbW = 160, kThumbH = 90, kBlockW = 10, kBlockH = 9;
}

cv::Mat change_thumbnail(const cv::Mat& bgr) {
  if (bgr.empty()) fail("change_thumbnail: empty frame");
  cv::Mat grey, small;
  if (bgr.channels() == 3) cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  else grey = bgr;
  cv::resize(grey, small, cv::Size(kThumbW, kThumbH), 0, 0, cv::INTER_AREA);
  cv::Mat f;
  small.convertTo(f, CV_32F);
  return f;
}

double frame_change(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) fail("frame_change: thumbnails of different sizes");
  cv::Mat d, blocks;
  cv::absdiff(a, b, d);
  cv::resize(d, blocks, cv::Size(a.cols / kBlockW, a.rows / kBlockH), 0, 0, cv::INTER_AREA);  // block means
  double lo, hi;
  cv::minMaxLoc(blocks, &lo, &hi);
  return hi;
}

std::vector<bool> find_repeats(const std::vector<double>& change, const RepeatOptions& opt) {
  const int64_t n = int64_t(change.size());
  std::vector<bool> repeat(size_t(n), false);
  for (int64_t i = 1; i < n; ++i) {
    const double c = change[size_t(i)];
    double around = 0;
    for (int64_t j = std::max<int64_t>(1, i - opt.window); j <= std::min(n - 1, i + opt.window); ++j)
      around = std::max(around, change[size_t(j)]);
    repeat[size_t(i)] = c <= opt.noise || c < std::min(opt.relative_cap, opt.relative * around);
  }
  return repeat;
}

double kept_frame_rate(const std::vector<double>& times) {
  if (times.size() < 2) return 0;
  std::vector<double> dt;
  for (size_t i = 1; i < times.size(); ++i) dt.push_back(times[i] - times[i - 1]);
  std::vector<double> sorted = dt;
  std::sort(sorted.begin(), sorted.end());
  const double p10 = sorted[sorted.size() / 10];
  double sum = 0;
  int64_t count = 0;
  for (double d : dt)
    if (d > 0 && d <= 2.5 * p10) {
      sum += d;
      ++count;
    }
  return count > 0 && sum > 0 ? double(count) / sum : 0;
}

}  // namespace gaia::data
