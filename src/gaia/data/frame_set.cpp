#include "gaia/data/frame_set.h"

#include "gaia/data/geofence.h"

namespace gaia::data {

FrameSet frame_set(const Dataset& ds, const std::vector<std::string>& ids, int margin, int n) {
  FrameSet s;
  std::vector<FrameRef> all;
  for (size_t e : episode_indices(ds, ids)) {
    s.episodes.push_back(std::make_unique<Episode>(ds.episode(e)));
    for (int64_t i = 0; i + margin < s.episodes.back()->size(); ++i) all.push_back({s.episodes.size() - 1, i});
  }
  if (n <= 0 || size_t(n) >= all.size()) {
    s.frames = std::move(all);
  } else {
    for (size_t k = 0; k < size_t(n); ++k) s.frames.push_back(all[k * all.size() / size_t(n)]);
  }
  return s;
}

FrameSet merge(FrameSet a, FrameSet b) {
  const size_t offset = a.episodes.size();
  for (auto& e : b.episodes) a.episodes.push_back(std::move(e));
  for (auto r : b.frames) a.frames.push_back({r.episode + offset, r.frame});
  return a;
}

std::vector<std::string> held_out_ids(const Dataset& ds, uint64_t seed) {
  auto ids = load_or_default_split(ds, kDefaultValFraction, seed).held_out();
  return ids.empty() ? ds.ids() : ids;
}

FrameSet held_out_frames(const Dataset& ds, uint64_t seed, int margin, int n) {
  return frame_set(ds, held_out_ids(ds, seed), margin, n);
}

}  // namespace gaia::data
