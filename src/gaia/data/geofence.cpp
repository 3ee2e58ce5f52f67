#include "gaia/data/geofence.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <map>
#include <random>

#include "gaia/core/error.h"
#include "gaia/core/hash.h"
#include "gaia/core/json_file.h"
#include "gaia/data/mirror.h"
#include "gaia/data/signals.h"

namespace gaia::data {

GeoBox parse_geobox(const std::string& s) {
  auto cells = split_csv_line(s, "--geofence '" + s + "'");
  if (cells.size() != 4) fail("--geofence '{}': expected lat_min,lon_min,lat_max,lon_max", s);
  double v[4];
  for (int i = 0; i < 4; ++i) {
    try {
      size_t used;
      v[i] = std::stod(cells[static_cast<size_t>(i)], &used);
      if (used != cells[static_cast<size_t>(i)].size()) throw std::invalid_argument("x");
    } catch (const std::exception&) {
      fail("--geofence '{}': '{}' is not a number", s, cells[static_cast<size_t>(i)]);
    }
  }
  GeoBox b{v[0], v[1], v[2], v[3]};
  if (!(b.lat_min < b.lat_max && b.lon_min < b.lon_max)) fail("--geofence '{}': min must be below max", s);
  return b;
}

std::vector<std::string> Split::held_out() const {
  std::vector<std::string> ids = val_geofence;
  ids.insert(ids.end(), val_named.begin(), val_named.end());
  ids.insert(ids.end(), val_random.begin(), val_random.end());
  return ids;
}

nlohmann::json Split::to_json() const {
  nlohmann::json j = {{"train", train}, {"val_geofence", val_geofence}, {"val_random", val_random}};
  if (!val_named.empty()) j["val_named"] = val_named;  // files written before it existed stay byte-identical
  return j;
}

Split Split::from_json(const nlohmann::json& j, const std::string& where) {
  Split s;
  try {
    s.train = j.at("train").get<std::vector<std::string>>();
    s.val_geofence = j.at("val_geofence").get<std::vector<std::string>>();
    s.val_random = j.at("val_random").get<std::vector<std::string>>();
    if (j.contains("val_named")) s.val_named = j.at("val_named").get<std::vector<std::string>>();
  } catch (const nlohmann::json::exception& e) {
    fail("{}: bad split file ({})", where, e.what());
  }
  return s;
}

Split geofence_split(const std::vector<EpisodeMeta>& episodes, const std::vector<GeoBox>& strict, double frac,
                     uint64_t seed, const std::vector<std::string>& named, const std::string& where) {
  if (!(frac >= 0 && frac < 1)) fail("validation fraction must be in [0, 1), got {}", frac);
  for (const auto& n : named) {
    bool found = false;
    for (const auto& m : episodes) found = found || split_source_id(m.id) == n || m.id == n;
    if (!found) fail("--hold-out {}: {} has no episode of that name", n, where.empty() ? "the dataset" : where);
  }
  Split s;
  for (const auto& m : episodes) {
    bool fenced = false;
    if (m.has_location())
      for (auto& b : strict) fenced = fenced || b.contains(m.latitude, m.longitude);
    const bool by_name = std::find(named.begin(), named.end(), m.id) != named.end() ||
                         std::find(named.begin(), named.end(), split_source_id(m.id)) != named.end();
    if (fenced) s.val_geofence.push_back(m.id);
    else if (by_name) s.val_named.push_back(m.id);
    else if (held_out_at_random(m.id, frac, seed)) s.val_random.push_back(m.id);
    else s.train.push_back(m.id);
  }
  return s;
}

Split geofence_split(const Dataset& ds, const std::vector<GeoBox>& strict, double frac, uint64_t seed,
                     const std::vector<std::string>& named) {
  std::vector<EpisodeMeta> metas;
  for (size_t i = 0; i < ds.size(); ++i) metas.push_back(ds.meta(i));
  return geofence_split(metas, strict, frac, seed, named, ds.root().string());
}

bool held_out_at_random(const std::string& id, double frac, uint64_t seed) {
  uint64_t h = fnv1a(split_source_id(id));  // a derived episode goes with its source
  std::mt19937_64 rng(seed ^ h);
  return std::uniform_real_distribution<double>(0, 1)(rng) < frac;
}

std::string split_source_id(const std::string& id) {
  std::string s = mirror_source_id(id);
  const size_t at = s.rfind(kCounterfactualInfix);
  const size_t digits = at == std::string::npos ? 0 : s.size() - at - std::strlen(kCounterfactualInfix);
  if (at == std::string::npos || at == 0 || digits == 0) return s;
  for (size_t i = s.size() - digits; i < s.size(); ++i)
    if (!std::isdigit(static_cast<unsigned char>(s[i]))) return s;
  return s.substr(0, at);
}

Split read_split(const fs::path& f) {
  return Split::from_json(read_json(f), f.string());
}

Split load_or_default_split(const Dataset& ds, double frac, uint64_t seed) {
  return load_or_default_split(ds.root(), ds.ids(), frac, seed);
}

Split load_or_default_split(const fs::path& root, const std::vector<std::string>& ids, double frac, uint64_t seed) {
  if (fs::exists(root / "split.json")) {
    Split s = read_split(root / "split.json");
    // Episodes added after the split was written (counterfactual replays, mirror images) go where the drive they
    // derive from is: a replay of a training drive trains, one of a held-out drive stays held out.
    std::map<std::string, std::vector<std::string>*> where;
    for (auto* list : {&s.train, &s.val_geofence, &s.val_random, &s.val_named})
      for (const auto& id : *list) where.emplace(id, list);
    for (const auto& id : ids) {
      if (where.count(id)) continue;
      const auto source = where.find(split_source_id(id));
      if (source != where.end()) source->second->push_back(id);
    }
    return s;
  }
  if (!(frac >= 0 && frac < 1)) fail("validation fraction must be in [0, 1), got {}", frac);
  Split s;
  for (auto& id : ids) (held_out_at_random(id, frac, seed) ? s.val_random : s.train).push_back(id);
  if (s.val_random.empty() && s.train.size() >= 2) {  // tiny datasets: hold out the last episode
    s.val_random.push_back(s.train.back());
    s.train.pop_back();
  }
  if (s.train.empty() && !s.val_random.empty()) {
    // The draw held out every episode: the first drive trains (with its mirror images and replays, which go with it).
    const std::string first = split_source_id(s.val_random.front());
    std::vector<std::string> keep;
    for (auto& id : s.val_random) (split_source_id(id) == first ? s.train : keep).push_back(id);
    s.val_random = keep;
  }
  return s;
}

std::vector<size_t> episode_indices(const Dataset& ds, const std::vector<std::string>& ids) {
  std::vector<size_t> out;
  for (auto& id : ids) {
    auto it = std::find(ds.ids().begin(), ds.ids().end(), id);
    if (it == ds.ids().end()) fail("{}: split names episode '{}' which is not in the dataset", ds.root().string(), id);
    out.push_back(static_cast<size_t>(it - ds.ids().begin()));
  }
  return out;
}

}  // namespace gaia::data
