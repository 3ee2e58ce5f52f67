#pragma once
// A rollout's choice of each image token (§5.1) on raw memory, the partner of the fused token step (token_step.h):
// the copy bias, classifier-free guidance (eq. 2), the conditional top-k constraint, then top-k sampling or argmax,
// in a few passes over each row's K logits. The LibTorch path (with_copy_bias, guide, keep_top_k, sample_tokens)
// spends about twenty-five calls a token on the same; both find the same candidates and draw with draw_token, so
// they choose the same tokens up to float rounding (tested).
#include <cstdint>

#include <torch/torch.h>

#include "gaia/world/sampling.h"

namespace gaia::world {

struct TokenChoice {
  static bool applies(const SamplingOptions& o);  // argmax, or top-k at a temperature > 0
  SamplingOptions sampling;
  bool guided = false;  // rows: N conditional, then N unconditional
  bool within = false;  // guided draws among the conditional top k (SamplingOptions::guide_actions_within_top_k)
  // logits [B, K] float32 row-major, B = 2N guided, else N; prev [B]: each row's token at this slot in the
  // previous frame, and bias [B] its copy logit (CopyBias::at; both nullptr: no copy bias); s: this token's guidance
  // scale. Writes N token ids to `out`.
  void operator()(const float* logits, int64_t N, int64_t K, const int64_t* prev, const float* bias, double s,
                  torch::Generator& gen, int64_t* out) const;
};

}  // namespace gaia::world
