#pragma once
// Attention's causal softmax on the CPU: p = softmax(scale * s) over the keys j <= i of query i (p = 0 after it) for
// square scores s [N, L, L], float32 statistics, float32 or bf16 in and out, differentiable. The forward and the
// backward pass are each one pass over the lower triangle; LibTorch 1.x's path adds a -inf mask over the whole
// square, takes a float32 softmax and casts it, and its backward pass casts, multiplies and casts again
// (docs/benchmarks.md, "The causal softmax").
#include <torch/torch.h>

namespace gaia {

bool causal_softmax_applies(const torch::Tensor& scores);  // CPU, [N, L, L] contiguous, float32 or bf16

torch::Tensor causal_softmax(const torch::Tensor& scores, double scale);

}  // namespace gaia
