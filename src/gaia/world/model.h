#pragma once
// GAIA-1's world model (§2.1, §2.3): an autoregressive transformer over interleaved text, image and action tokens.
//
//   inputs per step t:   c_t  [m, text_dim] -> text_proj          (or the learned null text when dropped)
//                        z_t  [n] ids       -> token_embedding
//                        a_t  [2] scalars   -> speed_proj, curvature_proj (one linear layer each; null if dropped)
//                                              (+ speed_mlp, curvature_mlp: 1 -> h -> d when world.action_mlp = h > 0)
//   + temporal_pos[t] (shared by the step) + spatial_pos[slot]    (factorised positions, §2.1)
//   -> n_layers pre-LN blocks (causal) -> ln_f -> head over K image codes
//
// The loss is the cross-entropy of the image tokens only (paper eq. 1).
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/world/batch.h"
#include "gaia/world/layout.h"
#include "gaia/world/transformer.h"

namespace gaia::world {

struct WorldModelImpl : torch::nn::Module {
  // n image tokens per frame and K codes come from the tokenizer; the rest from the config.
  WorldModelImpl(const WorldConfig& c, int64_t n, int64_t K);

  // Training / scoring: logits of every image token [B, T, n, K], each predicted from everything before it
  // (plus the copy bias, CopyBias below, on the previous frame's code at the same position).
  torch::Tensor forward(const WorldBatch& b);

  // ---- pieces for incremental sampling (world/rollout) ----
  // Embedded inputs with positions: step slots at temporal index t (0 <= t < T).
  torch::Tensor embed_text(const WorldBatch& b, int64_t t0 = 0);          // [B, T, m, d]
  torch::Tensor embed_image(const torch::Tensor& tokens, int64_t t0 = 0,  // tokens [B, T, k] (slots 0..k-1)
                            int64_t slot0 = 0);                           // -> [B, T, k, d]
  torch::Tensor embed_actions(const WorldBatch& b, int64_t t0 = 0);       // [B, T, l, d]
  torch::Tensor embed(const WorldBatch& b, int64_t t0 = 0);               // [B, T * S, d] whole steps
  // Runs the body over embedded tokens appended to the cache (or without a cache, causally from scratch):
  // x [B, L, d] -> ln_f output [B, L, d]; the cache length grows by L.
  torch::Tensor body(const torch::Tensor& x, KVCache* cache = nullptr);
  // As body with a cache, for tokens whose outputs are not needed (a prompt, actions, the re-encoded history of the
  // sliding window): their keys and values are appended to the cache, and the last block stops there.
  void prefill(const torch::Tensor& x, KVCache& cache);
  torch::Tensor logits(const torch::Tensor& h) { return head->forward(h); }  // [..., d] -> [..., K]
  // dtype: the weights' by default; bf16 halves what sampling reads per token (RolloutStepper under bf16 on the CPU).
  KVCache make_cache(int64_t batch, int64_t capacity, c10::optional<torch::ScalarType> dtype = c10::nullopt) const;

  int64_t parameter_count(bool with_word_embedding = true) const;

  WorldConfig cfg;
  SequenceLayout layout;
  int64_t K, d;
  torch::nn::Embedding token_embedding{nullptr};   // [K, d]
  torch::nn::Embedding word_embedding{nullptr};    // [text_vocab, text_dim]: the built-in text encoder
  torch::nn::Linear text_proj{nullptr};            // text_dim -> d
  torch::nn::Linear speed_proj{nullptr}, curvature_proj{nullptr};  // 1 -> d each (§2.1: one layer per action)
  torch::nn::Sequential speed_mlp{nullptr}, curvature_mlp{nullptr};  // 1 -> h -> d, added; only when action_mlp > 0
  torch::Tensor null_text, null_action;            // [m, d], [l, d] learned "no conditioning" tokens
  torch::Tensor temporal_pos, spatial_pos;         // [T, d], [S, d]
  torch::nn::ModuleList blocks{nullptr};
  torch::nn::LayerNorm ln_f{nullptr};
  torch::nn::Linear head{nullptr};                 // d -> K, no bias
};
TORCH_MODULE(WorldModel);

// world.copy_bias: logits [..., K] with bias [...] (one per position, cast to the logits' dtype) added at the code
// each position held one frame earlier, prev [...].
torch::Tensor with_copy_bias(const torch::Tensor& logits, const torch::Tensor& prev, const torch::Tensor& bias);

// The copy logit of image slot i: world.copy_bias, plus world.copy_bias_run where slot i - 1 of the same frame kept
// its previous frame's code (slot 0 never does). Causal in the raster order, so sampling knows it too.
struct CopyBias {
  double bias = 0, run = 0;
  static CopyBias of(const WorldConfig& c) { return {c.copy_bias, c.copy_bias_run}; }
  bool any() const { return bias != 0 || run != 0; }
  double at(bool run_before) const { return run_before ? bias + run : bias; }
  // Each slot's bias for frames cur [..., n] that follow prev [..., n]: float64 [..., n].
  torch::Tensor per_slot(const torch::Tensor& cur, const torch::Tensor& prev) const;
  // logits [B, T, n, K] of frames `tokens` [B, T, n]: frames 1.. biased at their previous frame's codes.
  torch::Tensor apply(const torch::Tensor& logits, const torch::Tensor& tokens) const;
};

// Mean cross-entropy over image tokens (paper eq. 1); logits [B, T, n, K], tokens [B, T, n].
torch::Tensor image_token_loss(const torch::Tensor& logits, const torch::Tensor& tokens);

}  // namespace gaia::world
