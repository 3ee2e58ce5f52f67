#pragma once
// `gaia world eval` as one call: the world model on a token dataset's held-out windows. Cross-entropy in each
// conditioning mode and with the conditioning shuffled (does the model use it?), bits per token against xz and
// zstd on the same token stream, the steering sensitivity, perplexity by token position, and the paper's Fig. 5:
// each window's last frame as argmax, top-k and full sampling draw it, scored like the real one.
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gaia/core/fs.h"
#include "gaia/world/footage.h"
#include "gaia/world/io.h"
#include "gaia/world/model.h"
#include "gaia/world/token_dataset.h"

namespace gaia::world {

struct WorldEvalOptions {
  size_t max_windows = 256;         // held-out windows of T steps to score
  std::vector<int> top_k_sweep;     // Fig. 5 strategies: k per draw (1 = argmax, 0 = whole distribution);
                                    // empty = 1, world.top_k, 0
  size_t sweep_windows = 64;        // windows whose last frame each strategy draws
  std::string name, weights;        // recorded in the result: the token dataset and the weights file
  Footage footage = Footage::kAny;  // which held-out episodes are scored: a dataset of both scores each apart
};

// Scores `model` on the held-out episodes of `ds` (every episode when none is held out, e.g. a bare .npy) and
// returns eval.json's content. progress(done, total) after each scoring pass.
nlohmann::json evaluate_world(WorldModel& model, const WorldInfo& info, const TokenDataset& ds,
                              const WorldEvalOptions& o, const std::function<void(int, int)>& progress = {});

// OUT/eval.json, OUT/perplexity_by_position.svg and OUT/perplexity_by_strategy.svg from evaluate_world's result.
void write_world_eval(const nlohmann::json& result, const fs::path& out);

}  // namespace gaia::world
