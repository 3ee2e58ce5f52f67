#pragma once
// Frames spread evenly over a set of episodes, for evaluation. Taking the first N frames of the first episodes would
// score a few drives (one weather, one time of day); spreading them over every episode scores the whole set.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "gaia/data/episode.h"

namespace gaia::data {

struct FrameRef {
  size_t episode;  // index into FrameSet::episodes
  int64_t frame;   // frame index in that episode
};

struct FrameSet {
  std::vector<std::unique_ptr<Episode>> episodes;  // each opened once
  std::vector<FrameRef> frames;
};

// The episodes `ids`, and n frames evenly spaced over all their frames taken together (every frame if n <= 0).
// `margin` frames at the end of each episode are left out (for inputs that reach `margin` frames ahead).
FrameSet frame_set(const Dataset& ds, const std::vector<std::string>& ids, int margin, int n);
// Both sets in one: b's episodes after a's, its frames renumbered to match.
FrameSet merge(FrameSet a, FrameSet b);
// The held-out episodes of the dataset's split (data/geofence.h), or every episode when none is held out.
std::vector<std::string> held_out_ids(const Dataset& ds, uint64_t seed);
// The same over the held-out episodes of the dataset's split (data/geofence.h), or every episode when none is held out.
FrameSet held_out_frames(const Dataset& ds, uint64_t seed, int margin, int n);

}  // namespace gaia::data
