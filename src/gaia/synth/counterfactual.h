#pragma once
// Counterfactual augmentation: replays of a procedural dataset's drives that follow the recorded driving for a
// while and then hold a random steering command (synth::replay renders them, so the agents react and the frames,
// labels and captions stay consistent).
//
// Why: a lane-keeping driver never turns hard on a straight road, so a world model trained on its drives has
// seen few strong turns from the states a video prompt shows, and cannot tell a commanded strong right turn from
// a left one. The procedural world can show it what the command does from exactly those states. The paper's real data has no such counterfactuals; this is the
// synthetic world's advantage, used for training only on the training split.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "gaia/core/fs.h"
#include "gaia/data/episode.h"

namespace gaia::synth {

struct CounterfactualOptions {
  int per_episode = 4;           // replays of each source episode, each from its own random start
  double lead_seconds = 1.5;     // recorded driving before the command (longer than gaia eval's prompts)
  double hold_seconds = 2.0;     // the command held (longer than gaia eval's rollouts)
  double max_curvature = 0.045;  // 1/m; drawn uniformly in [-max, max] (beyond gaia eval's strongest commands)
  double min_speed = 3.0;        // the command keeps the recorded speed at its start, at least this (m/s; as gaia eval)
  uint64_t seed = 0;
};

// Id of replay k of episode `source_id`: "<source_id>-cf<k, 2 digits>"; data::split_source_id maps it back, so the
// replay is held out exactly when its source is.
std::string counterfactual_id(const std::string& source_id, int k);

// Writes opt.per_episode replays of each episode of `ids` into `out` and returns how many it wrote. Replays
// already in `out` are kept (the job resumes per replay); episodes shorter than lead + hold are skipped. Each
// replay is deterministic in (seed, source id, k). progress(done, total) counts replays.
int64_t write_counterfactuals(const data::Dataset& ds, const std::vector<std::string>& ids,
                              const CounterfactualOptions& opt, const fs::path& out,
                              std::function<void(int64_t done, int64_t total)> progress = {});

}  // namespace gaia::synth
