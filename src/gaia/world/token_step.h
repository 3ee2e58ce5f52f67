#pragma once
// Sampling's inner step (§5.1) made cheap on the CPU: one new image token per row through the embedding, every
// block and the head, in float32 on raw memory. The general path (WorldModelImpl::body, then logits) spends about
// fifteen LibTorch calls per block on a single token, each dearer than its arithmetic; here a block is a handful of
// loops over weights packed once, so that every product is contiguous multiply-adds. Same numbers as the
// general path up to float rounding (tested); a rollout takes this path where applies() says so.
#include <memory>

#include <torch/torch.h>

#include "gaia/world/model.h"

namespace gaia::world {

class TokenStep {
 public:
  static constexpr int64_t kMaxRows = 4;  // beyond this a row-by-row product loses to LibTorch's matrix product
  // CPU, float32 weights, and few rows (many rows make real matrix products, which LibTorch does well). Under bf16's
  // autocast (--precision bf16) too: the step itself stays float32, as the cached attention does in the general
  // path (its matrices stored as bf16 gained nothing: docs/benchmarks.md).
  static bool applies(const WorldModelImpl& model, int64_t rows);
  // Copies the weights, matrices packed for the products: as much memory again as the model. Later changes to the model's
  // weights are not seen (make a new TokenStep).
  explicit TokenStep(const WorldModelImpl& model);

  // tokens [B] (int64) at temporal index t and image slot `slot` are appended to `cache` (every layer's key and
  // value, length + 1) -> the logits [B, K] (float32) that predict the next token: ln_f and head applied.
  torch::Tensor logits(const torch::Tensor& tokens, int64_t t, int64_t slot, KVCache& cache) const;

 private:
  struct Layer {
    torch::Tensor ln1_w, ln1_b, qkv_p, qkv_b, proj_p, proj_b, ln2_w, ln2_b, fc_p, fc_b, fc_proj_p, fc_proj_b;
    double eps1 = 1e-5, eps2 = 1e-5;
  };
  int64_t d_, K_, heads_, image_slot0_;
  torch::Tensor embedding_, temporal_, spatial_;  // [K, d], [T, d], [S, d]
  std::vector<Layer> layers_;
  torch::Tensor lnf_w_, lnf_b_, head_p_;          // the head packed
  double eps_f_ = 1e-5;
};

}  // namespace gaia::world
