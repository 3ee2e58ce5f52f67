#pragma once
// Geofenced validation split (paper §3): episodes inside a strict geofence are validation-only (roads never seen
// in training); a random selection of the remaining episodes can be held out as well.
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gaia/data/episode.h"

namespace gaia::data {

struct GeoBox {
  double lat_min = 0, lon_min = 0, lat_max = 0, lon_max = 0;
  bool contains(double lat, double lon) const {
    return lat >= lat_min && lat <= lat_max && lon >= lon_min && lon <= lon_max;
  }
};

GeoBox parse_geobox(const std::string& s);  // "lat_min,lon_min,lat_max,lon_max"

struct Split {
  // val_named: held out by name (`gaia data split --hold-out ID`, e.g. one clip for a leave-one-out measurement).
  std::vector<std::string> train, val_geofence, val_random, val_named;
  // Every held-out episode: the geofenced ones first, then those held out by name, then the random hold-out.
  std::vector<std::string> held_out() const;
  nlohmann::json to_json() const;
  static Split from_json(const nlohmann::json& j, const std::string& where);
};

// Episodes without a location are never geofenced; random hold-out is seeded and independent of order. `named`
// episodes (and the mirror images and replays derived from them) are held out whatever their place; a name that
// matches no episode is an error.
Split geofence_split(const std::vector<EpisodeMeta>& episodes, const std::vector<GeoBox>& strict,
                     double random_val_fraction, uint64_t seed, const std::vector<std::string>& named = {},
                     const std::string& where = "");
Split geofence_split(const Dataset& ds, const std::vector<GeoBox>& strict, double random_val_fraction, uint64_t seed,
                     const std::vector<std::string>& named = {});

// The random hold-out decision for one episode: a hash of (seed, id), so it does not change when episodes are added.
// An episode derived from another hashes its source's id (split_source_id): it is held out exactly when its source
// is, so a validation drive never reaches training in another form.
bool held_out_at_random(const std::string& id, double frac, uint64_t seed);

// Counterfactual replays of a drive are `<source id>-cf<k>` (synth/counterfactual.h).
inline constexpr const char* kCounterfactualInfix = "-cf";
// The drive an episode derives from: "e1-mirror" -> "e1" (data/mirror.h), "e1-cf03" and "e1-cf03-mirror" -> "e1";
// any other id unchanged.
std::string split_source_id(const std::string& id);

Split read_split(const fs::path& file);  // a split.json; errors name the file

// The share of episodes the default split holds out at random.
constexpr double kDefaultValFraction = 0.1;

// DATASET/split.json when present (from `gaia data split`; an episode it does not name joins the list of the drive it
// derives from, split_source_id, e.g. replays tokenized into a token dataset later), otherwise a seeded random
// hold-out of `frac` of the episodes (at least one when there are two or more, and never all of them) so that
// training always has a validation set and a training set.
Split load_or_default_split(const Dataset& ds, double frac = kDefaultValFraction, uint64_t seed = 0);
// The same for any directory of episodes `ids` (e.g. a token dataset, which carries its source's split.json).
Split load_or_default_split(const fs::path& root, const std::vector<std::string>& ids, double frac = kDefaultValFraction,
                            uint64_t seed = 0);
std::vector<size_t> episode_indices(const Dataset& ds, const std::vector<std::string>& ids);  // ids -> Dataset indices

}  // namespace gaia::data
