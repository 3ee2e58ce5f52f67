#pragma once
// Steps [start, start + P) of a token-dataset episode as a video prompt: what `gaia generate` and `gaia sim` take.
#include <torch/torch.h>

#include "gaia/world/token_dataset.h"

namespace gaia::app {

struct EpisodePrompt {
  torch::Tensor tokens;   // [P, n] int64
  torch::Tensor actions;  // [P, 2] recorded speed (m/s) and curvature (1/m), NaN where unknown
};

inline EpisodePrompt episode_prompt(world::TokenDataset& ds, size_t e, int64_t start, int64_t P) {
  const int64_t n = ds.tokens_per_step();
  auto ep = ds.episode(e);
  return {torch::from_blob(const_cast<int32_t*>(ep->tokens.data()) + start * n, {P, n}, torch::kInt).to(torch::kLong),
          torch::from_blob(const_cast<float*>(ds.actions(e).data()) + start * 2, {P, 2}, torch::kFloat).clone()};
}

}  // namespace gaia::app
