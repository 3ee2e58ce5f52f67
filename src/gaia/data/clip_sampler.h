#pragma once
// Clips of T frames at a target rate, chosen by timestamps (paper §2.3: 25 Hz -> 6.25 Hz is every 4th frame;
// a 30 fps source gives frames 0, 5, 10, 14, ... the nearest to k / 6.25 s).
#include <cstdint>
#include <random>
#include <vector>

#include "gaia/data/episode.h"

namespace gaia::data {

// Frame indices nearest to start + k / rate for k = 0..T-1; empty if the clip runs past the episode
// (a target time more than half a source frame after the last frame).
std::vector<int64_t> clip_indices(const std::vector<double>& times, double start_time, int T, double rate);

struct ClipRef {
  size_t episode = 0;            // index into Dataset::ids()
  std::vector<int64_t> frames;   // T frame indices
};

// Every clip of an episode list whose start frames are `stride_s` seconds apart (streams episode by episode;
// only timestamps are read, never frames).
std::vector<ClipRef> enumerate_clips(const Dataset& ds, const std::vector<size_t>& episodes, int T, double rate,
                                     double stride_s);

// `count` clips spread over an episode list, for evaluation: clip i comes from episodes[i * E / count], starting a
// fraction (i + 0.5) / count of the way through that episode's possible starts. The first clip of the first few
// episodes would score a few drive starts (one weather, the car pulling away); this scores the whole set.
// Episodes too short for a clip are skipped, so fewer than `count` may come back.
std::vector<ClipRef> spread_clips(const Dataset& ds, const std::vector<size_t>& episodes, int T, double rate, int count);

}  // namespace gaia::data
