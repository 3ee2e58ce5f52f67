#pragma once
// Scaled dot-product attention (Vaswani et al. 2017), the one implementation every model calls: the world model's
// causal self-attention (§2.1), the video decoder's spatial and temporal attention (§2.4) and the DINO teacher's
// ViT blocks. On LibTorch 2 it is the fused kernel; on 1.x a causal square being trained on the CPU goes through
// causal_softmax.h (one pass over the lower triangle each way), and an additive mask is fused into the score product
// (baddbmm: one pass over the L x L scores instead of three).
#include <torch/torch.h>

namespace gaia {

// q [..., Lq, hd], k and v [..., Lk, hd] -> [..., Lq, hd]: softmax(q k^T / sqrt(hd) + bias) v. `bias` is added to
// the scores (undefined = none; [Lq, Lk] or broadcastable to [..., Lq, Lk]); `causal` masks key j > query i, for a
// square score matrix.
torch::Tensor attention(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v,
                        const torch::Tensor& bias = {}, bool causal = false);

// The additive causal mask [Lq, Lk] of queries at key positions offset .. offset + Lq - 1: 0 where the key is at or
// before the query, -inf after it.
torch::Tensor causal_mask(int64_t Lq, int64_t Lk, int64_t offset, const torch::TensorOptions& options);

}  // namespace gaia
