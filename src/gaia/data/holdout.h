#pragma once
// Held-out clips chosen by group (`gaia data split --hold-out-by source_repo,place`): clips of one source share a
// driver, a camera and often a road, so whole groups are held out and no held-out clip shares a drive with a
// training clip. A group is the clips with the same value of every key, each value compared by its text before the
// first comma or parenthesis, in lower case (place is free text: "Seattle, USA (downtown)" and "Seattle, USA
// (elevated freeway)" are one place).
// Groups are picked so that every value of each `cover` key (weather, time of day, road) that two or more groups
// hold has a held-out group holding it, then, smallest first, until `fraction` of the frames are held out. A group
// is never held out where that would leave a value with no training group, so a condition that one group alone
// holds stays in training.
#include <cstdint>
#include <string>
#include <vector>

#include "gaia/data/episode.h"

namespace gaia::data {

// The value of `key` for an episode: its weather or time_of_day field, else its metadata (`extra`); "" = none.
std::string meta_value(const EpisodeMeta& m, const std::string& key);

struct GroupHoldOut {
  std::vector<std::string> episodes;  // the held-out episode ids
  std::vector<std::string> groups;    // the held-out groups, in the order they were picked
  std::vector<std::string> uncovered;  // "key=value" held by a single group (or whose groups had to stay in training)
  int64_t frames = 0, total_frames = 0;
};

// `keys`: one or more metadata keys. An episode without any of them is a group of its own. The pick is deterministic for a seed (ties broken by a hash of
// the group name and the seed).
GroupHoldOut hold_out_groups(const std::vector<EpisodeMeta>& episodes, const std::vector<std::string>& keys,
                             const std::vector<std::string>& cover, double fraction, uint64_t seed);

}  // namespace gaia::data
