#include "gaia/data/holdout.h"

#include <algorithm>
#include <map>
#include <set>

#include "gaia/core/error.h"
#include "gaia/core/hash.h"

namespace gaia::data {

std::string meta_value(const EpisodeMeta& m, const std::string& key) {
  if (key == "weather") return m.weather;
  if (key == "time_of_day") return m.time_of_day;
  if (key == "source") return m.source;
  auto it = m.extra.find(key);
  return it == m.extra.end() ? "" : it->second;
}

namespace {

uint64_t tie_break(const std::string& s, uint64_t seed) { return fnv1a(s, kFnvBasis ^ (seed * 0x9E3779B97F4A7C15ull)); }

std::string group_value(const std::string& v) {
  std::string s = v.substr(0, v.find_first_of(",("));
  const auto b = s.find_first_not_of(" \t"), e = s.find_last_not_of(" \t");
  s = b == std::string::npos ? "" : s.substr(b, e - b + 1);
  std::transform(s.begin(), s.end(), s.begin(), ::tolower);
  return s;
}

struct Group {
  std::vector<std::string> ids;
  int64_t frames = 0;
  std::set<std::string> values;  // "key=value"
  bool held = false;
};

}  // namespace

GroupHoldOut hold_out_groups(const std::vector<EpisodeMeta>& episodes, const std::vector<std::string>& keys,
                             const std::vector<std::string>& cover, double fraction, uint64_t seed) {
  if (keys.empty()) fail("--hold-out-by: name one or more metadata keys (e.g. source_repo,place)");
  if (!(fraction >= 0 && fraction < 1)) fail("--val-fraction {}: must be in [0, 1)", fraction);
  std::map<std::string, Group> groups;
  GroupHoldOut out;
  for (const auto& m : episodes) {
    std::string g;
    bool any = false;
    for (const auto& k : keys) {
      const std::string v = group_value(meta_value(m, k));
      any = any || !v.empty();
      g += (g.empty() ? "" : " | ") + v;
    }
    if (!any) g = "episode:" + m.id;
    Group& gr = groups[g];
    gr.ids.push_back(m.id);
    gr.frames += m.num_frames;
    out.total_frames += m.num_frames;
    for (const auto& c : cover) {
      const std::string v = meta_value(m, c);
      if (!v.empty()) gr.values.insert(c + "=" + v);
    }
  }
  if (groups.size() < 2)
    fail("--hold-out-by: the episodes form {} group; holding it out leaves nothing to train on", groups.size());
  // How many training groups still hold each value.
  std::map<std::string, int> training;
  for (auto& [name, g] : groups)
    for (auto& v : g.values) ++training[v];
  std::set<std::string> covered;
  auto safe = [&](const Group& g) {
    if (g.held) return false;
    for (auto& v : g.values)
      if (training[v] < 2) return false;
    return true;
  };
  auto take = [&](const std::string& name) {
    Group& g = groups[name];
    g.held = true;
    for (auto& v : g.values) {
      --training[v];
      covered.insert(v);
    }
    out.groups.push_back(name);
    out.frames += g.frames;
    out.episodes.insert(out.episodes.end(), g.ids.begin(), g.ids.end());
  };
  // 1. Cover every value that two or more groups hold: the group covering the most values still uncovered per frame.
  for (;;) {
    std::string best;
    double best_score = 0;
    uint64_t best_tie = 0;
    for (auto& [name, g] : groups) {
      if (!safe(g)) continue;
      int fresh = 0;
      for (auto& v : g.values) fresh += !covered.count(v);
      if (fresh == 0) continue;
      const double score = double(fresh) / double(std::max<int64_t>(1, g.frames));
      const uint64_t tie = tie_break(name, seed);
      if (best.empty() || score > best_score || (score == best_score && tie < best_tie)) {
        best = name;
        best_score = score;
        best_tie = tie;
      }
    }
    if (best.empty()) break;
    take(best);
  }
  // 2. Up to the fraction of frames: the smallest groups that can go.
  while (double(out.frames) < fraction * double(out.total_frames)) {
    std::string best;
    for (auto& [name, g] : groups)
      if (safe(g) && (best.empty() || g.frames < groups[best].frames ||
                      (g.frames == groups[best].frames && tie_break(name, seed) < tie_break(best, seed))))
        best = name;
    if (best.empty()) break;
    take(best);
  }
  for (auto& [v, n] : training)
    if (!covered.count(v)) out.uncovered.push_back(v);
  return out;
}

}  // namespace gaia::data
