#pragma once
// Multiple futures and long rollouts (§5 of the paper shows both as videos):
//   futures   N futures from one held-out prompt: how different they are (mean pairwise token distance) while
//             staying plausible (FD-probe of their frames to real held-out frames, with real-vs-real as the floor)
//   long      a minute of driving with the sliding window, from several held-out prompts at once: per 10 s window,
//             the copy rate (tokens equal to the previous frame's at the same position), the unigram entropy of
//             the tokens and FD-probe to real frames, averaged over the rollouts, against the same statistics of
//             real held-out token episodes: no collapse into repetition and no drift. One drive's windows vary as
//             much as real drives do (a stop at a junction copies twice as much as the mean), so the comparison is
//             of means, each with its standard error
#include "gaia/emerging/common.h"
#include "gaia/world/sampling.h"

namespace gaia::emerging {

struct RolloutEvalOptions {
  int prompts = 8, prompt_frames = 3, frames = 5, futures = 4;
  double long_seconds = 60;     // 0 skips the long rollout
  double window_seconds = 10;
  int long_rollouts = 8;        // long rollouts, each from another held-out prompt, batched
  world::SamplingOptions sampling;
  Footage footage = Footage::kAny;  // which held-out episodes give the prompts and the real reference
  uint64_t seed = 0;
};

// Statistics of token frames [S, n] (exposed for tests): mean fraction of tokens equal to the previous frame's,
// and the entropy (bits) of the token histogram.
double copy_rate(const torch::Tensor& frames);
double unigram_entropy_bits(const torch::Tensor& frames, int64_t K);

nlohmann::json futures_diversity(Models& m, const world::TokenDataset& ds, const RolloutEvalOptions& o, Output& out);
nlohmann::json long_rollout(Models& m, const world::TokenDataset& ds, const RolloutEvalOptions& o, Output& out);

}  // namespace gaia::emerging
