#include "gaia/synth/counterfactual.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "gaia/core/error.h"
#include "gaia/data/geofence.h"
#include "gaia/synth/rng.h"
#include "gaia/synth/synth.h"

namespace gaia::synth {

std::string counterfactual_id(const std::string& source_id, int k) {
  return fmt::format("{}{}{:02d}", source_id, data::kCounterfactualInfix, k);
}

int64_t write_counterfactuals(const data::Dataset& ds, const std::vector<std::string>& ids,
                              const CounterfactualOptions& opt, const fs::path& out,
                              std::function<void(int64_t done, int64_t total)> progress) {
  if (opt.per_episode < 1) fail("counterfactuals: per_episode must be >= 1, got {}", opt.per_episode);
  if (!(opt.lead_seconds >= 0) || !(opt.hold_seconds > 0))
    fail("counterfactuals: lead must be >= 0 s and hold > 0 s, got {} and {}", opt.lead_seconds, opt.hold_seconds);
  if (!(opt.max_curvature >= 0 && opt.max_curvature <= 1))
    fail("counterfactuals: max_curvature must be in [0, 1] 1/m, got {}", opt.max_curvature);
  if (!(opt.min_speed >= 0 && opt.min_speed <= 70)) fail("counterfactuals: min_speed must be in [0, 70] m/s, got {}", opt.min_speed);
  const auto index = data::episode_indices(ds, ids);
  const int64_t total = static_cast<int64_t>(ids.size()) * opt.per_episode;
  int64_t done = 0, written = 0;
  for (size_t e = 0; e < ids.size(); ++e) {
    const data::Episode src = ds.episode(index[e]);
    const double fps = src.meta().fps;
    const int64_t lead = std::llround(opt.lead_seconds * fps), hold = std::max<int64_t>(1, std::llround(opt.hold_seconds * fps));
    for (int k = 0; k < opt.per_episode; ++k, ++done) {
      if (progress) progress(done, total);
      const std::string id = counterfactual_id(ids[e], k);
      if (src.size() < lead + hold || fs::exists(out / "episodes" / id / "episode.json")) continue;
      // One stream per (seed, source, k): the replay does not depend on which other replays are made.
      Rng r(stream_key(opt.seed, hash_tag(ids[e]), "counterfactual", static_cast<uint64_t>(k)));
      const int64_t from = r.integer(0, static_cast<int>(src.size() - lead - hold));
      const double curvature = r.uniform(-opt.max_curvature, opt.max_curvature);
      std::vector<ActionStep> actions;
      actions.reserve(static_cast<size_t>(lead + hold));
      for (int64_t i = from; i < from + lead; ++i) actions.push_back({src.speed(i), src.curvature(i)});
      const double speed = std::max<double>(opt.min_speed, src.speed(from + lead));
      actions.insert(actions.end(), static_cast<size_t>(hold), ActionStep{speed, curvature});
      replay(src, from, actions, out, id);
      ++written;
    }
  }
  if (progress) progress(total, total);
  return written;
}

}  // namespace gaia::synth
