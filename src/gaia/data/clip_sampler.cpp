#include "gaia/data/clip_sampler.h"

#include <algorithm>
#include <cmath>

#include "gaia/core/error.h"

namespace gaia::data {

std::vector<int64_t> clip_indices(const std::vector<double>& times, double start_time, int T, double rate) {
  if (times.empty() || T <= 0 || !(rate > 0)) return {};
  const double half_frame = times.size() > 1 ? 0.5 * (times.back() - times.front()) / double(times.size() - 1) : 0.0;
  std::vector<int64_t> out;
  out.reserve(static_cast<size_t>(T));
  for (int k = 0; k < T; ++k) {
    double t = start_time + k / rate;
    if (t > times.back() + half_frame + 1e-9) return {};
    auto it = std::lower_bound(times.begin(), times.end(), t);
    size_t i = static_cast<size_t>(it - times.begin());
    if (i == times.size()) i = times.size() - 1;
    else if (i > 0 && (t - times[i - 1]) <= (times[i] - t)) i = i - 1;  // nearest, ties to the earlier frame
    out.push_back(static_cast<int64_t>(i));
  }
  return out;
}

std::vector<ClipRef> enumerate_clips(const Dataset& ds, const std::vector<size_t>& episodes, int T, double rate,
                                     double stride_s) {
  if (!(stride_s > 0)) fail("clip stride must be positive");
  std::vector<ClipRef> out;
  for (size_t e : episodes) {
    Episode ep = ds.episode(e);
    const auto& times = ep.times();
    for (double t0 = times.front();; t0 += stride_s) {
      auto idx = clip_indices(times, t0, T, rate);
      if (idx.empty()) break;
      out.push_back(ClipRef{e, std::move(idx)});
    }
  }
  return out;
}

std::vector<ClipRef> spread_clips(const Dataset& ds, const std::vector<size_t>& episodes, int T, double rate, int count) {
  std::vector<ClipRef> out;
  const size_t E = episodes.size();
  for (int i = 0; i < count && E > 0; ++i) {
    const size_t e = episodes[size_t(i) * E / size_t(count)];
    Episode ep = ds.episode(e);
    const auto& times = ep.times();
    // the last start that still fits: a clip spans (T - 1) / rate seconds
    const double last = times.back() - (T - 1) / rate;
    if (last < times.front()) continue;
    const double t0 = times.front() + (last - times.front()) * (i + 0.5) / count;
    auto idx = clip_indices(times, t0, T, rate);
    if (idx.empty()) idx = clip_indices(times, times.front(), T, rate);  // rounding at the very end
    if (!idx.empty()) out.push_back(ClipRef{e, std::move(idx)});
  }
  return out;
}

}  // namespace gaia::data
