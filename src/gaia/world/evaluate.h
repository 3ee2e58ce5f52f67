#pragma once
// Scoring the world model on held-out windows: cross-entropy of the image tokens (nats; bits/token = nats / ln 2)
// in one conditioning mode, optionally with the conditioning shuffled across examples (does the model use it?),
// and per position within the frame (the paper's Fig. 5).
#include <vector>

#include "gaia/world/model.h"
#include "gaia/world/token_dataset.h"

namespace gaia::world {

struct ScoreOptions {
  Conditioning mode = Conditioning::kAction;
  bool shuffle = false;    // conditioning of window i taken from window perm(i), a fixed derangement
  int64_t batch = 8;
};

struct Score {
  double nats = 0;                    // mean cross-entropy per image token
  double bits() const;                // nats / ln 2
  std::vector<double> by_position;    // [n] mean cross-entropy of the i-th token of a frame
  int64_t tokens = 0;                 // image tokens scored
};

Score score(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows, const text::Vocab* vocab,
            const ScoreOptions& o);

// Evenly spaced windows of `T` steps from the given episodes, at most `max_windows` (fixed, for validation).
std::vector<Window> validation_windows(const TokenDataset& ds, const std::vector<size_t>& episodes, int64_t T,
                                       size_t max_windows);

}  // namespace gaia::world
