#pragma once
// Choosing the next image token from logits (§5.1, Fig. 5): argmax, sampling from the full distribution, top-k
// (the paper's choice, k = 50) and, as an extra, top-p (nucleus). Temperature divides the logits first.
#include <string>

#include <torch/torch.h>

namespace gaia::world {

enum class Strategy { Argmax, Sample, TopK, TopP };
Strategy parse_strategy(const std::string& s);  // "argmax" | "sample" | "top-k" | "top-p"; errors list the choices
std::string to_string(Strategy s);

struct SamplingOptions {
  Strategy strategy = Strategy::TopK;
  int top_k = 50;            // paper §5.1
  double top_p = 0.9;
  double temperature = 1.0;
  // Guidance on the actions alone, with top-k: draw only from the conditional logits' top k, re-weighted by the
  // guided ones (keep_top_k below; the plausibility constraint of contrastive decoding, Li et al. 2023).
  // Unconstrained, the large scales steering needs turn rollouts to noise within a few frames. Text guidance is
  // left free: a weather change such as fog needs codes the conditional ranks low, which the constraint would cut.
  bool guide_actions_within_top_k = true;
};

// logits [B, K] -> token ids [B] (int64). Random draws come from `gen` only, so rollouts are reproducible.
torch::Tensor sample_tokens(const torch::Tensor& logits, const SamplingOptions& o, torch::Generator& gen);

// One token drawn from n candidates (ids ascending, weights proportional to their probabilities): the inverse of
// the cumulative weights at one uniform number from `gen`. Top-k sampling draws with this on every path (the
// LibTorch one above, the rollout's raw one in token_choice.h), so that paths finding the same candidates and
// weights draw the same token from the same stream.
int64_t draw_token(const int64_t* ids, const float* weights, int64_t n, torch::Generator& gen);

// logits [B, K] with every entry outside the k highest of `ranking` [B, K] set to -inf (exactly k by rank: a
// threshold on the k-th value would let ties through). Top-k filtering is keep_top_k(l, l, k); guided logits kept
// to the conditional model's candidates are keep_top_k(guided, cond, k).
torch::Tensor keep_top_k(const torch::Tensor& logits, const torch::Tensor& ranking, int64_t k);

// The filtered, renormalised distribution sample_tokens draws from: [B, K] probabilities (argmax: one-hot).
torch::Tensor sampling_distribution(const torch::Tensor& logits, const SamplingOptions& o);

}  // namespace gaia::world
