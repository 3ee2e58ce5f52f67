#include "gaia/data/frame_sampler.h"

#include <algorithm>

#include "gaia/core/error.h"

namespace gaia::data {

FrameSampler::FrameSampler(const Dataset& ds, std::vector<size_t> episodes, int height, int width,
                           const std::vector<std::string>& balance, double exponent, int bins) {
  if (episodes.empty()) fail("{}: no episodes to sample frames from", ds.root().string());
  std::vector<FeatureRow> rows;
  std::vector<FeatureRow> per_episode;
  for (size_t e : episodes) {
    auto ep = std::make_unique<Episode>(ds.episode(e));
    if (ep->meta().height != height || ep->meta().width != width)
      fail("{}: frames are {}x{}, the config wants {}x{} (re-ingest, or set data.height/data.width)", ep->dir().string(),
           ep->meta().height, ep->meta().width, height, width);
    std::vector<int64_t> all(static_cast<size_t>(ep->size()));
    for (int64_t i = 0; i < ep->size(); ++i) all[static_cast<size_t>(i)] = i;
    per_episode.push_back(clip_features(*ep, all));
    for (int64_t i = 0; i < ep->size(); ++i) rows.push_back(per_episode.back());  // one row per frame
    total_ += ep->size();
    cum_.push_back(total_);
    episodes_.push_back(std::move(ep));
  }
  if (balance.empty() || exponent == 0) {
    keep_.assign(episodes_.size(), 1.0);
    return;
  }
  Balancer b(balance, exponent, bins);
  b.fit(rows);
  for (auto& r : per_episode) keep_.push_back(b.keep_probability(r));
}

std::vector<std::pair<size_t, int64_t>> FrameSampler::sample(size_t n, std::mt19937_64& rng) const {
  std::vector<std::pair<size_t, int64_t>> out;
  std::uniform_int_distribution<int64_t> pick(0, total_ - 1);
  std::uniform_real_distribution<double> u(0, 1);
  while (out.size() < n) {
    int64_t g = pick(rng);
    size_t e = static_cast<size_t>(std::upper_bound(cum_.begin(), cum_.end(), g) - cum_.begin());
    if (u(rng) >= keep_[e]) continue;  // balancing: stochastic rejection (paper §3)
    out.emplace_back(e, g - (e ? cum_[e - 1] : 0));
  }
  return out;
}

}  // namespace gaia::data
