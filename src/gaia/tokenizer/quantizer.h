#pragma once
// Vector quantiser (van den Oord et al. 2017) with the factorised, L2-normalised codes of Yu et al. 2022 that the
// paper adopts (§2.2) to raise codebook usage: features are projected to a low dimension, normalised, and matched
// to the nearest normalised codebook entry (cosine similarity); gradients pass straight through.
#include <torch/torch.h>

namespace gaia::tokenizer {

struct QuantizerOutput {
  torch::Tensor z_q;           // [B, z_channels, h, w] quantised features, projected back (straight-through)
  torch::Tensor codes;         // [B, code_dim, h, w] the normalised code vectors (for the DINO head / PCA)
  torch::Tensor indices;       // [B, h, w] int64 token ids in [0, K)
  torch::Tensor codebook_loss; // ||sg(z_e) - e||^2 (moves codes)
  torch::Tensor commit_loss;   // ||z_e - sg(e)||^2 (keeps the encoder close to the codes)
};

struct VectorQuantizerImpl : torch::nn::Module {
  VectorQuantizerImpl(int64_t z_channels, int64_t code_dim, int64_t codebook_size);
  QuantizerOutput forward(const torch::Tensor& z);        // z [B, z_channels, h, w]
  torch::Tensor lookup(const torch::Tensor& indices);     // [B, h, w] -> z_q [B, z_channels, h, w]
  torch::Tensor normalized_codebook() const;              // [K, code_dim]
  // Replaces codes unused in `usage` ([K] counts) with random recent encoder outputs `z_e` ([N, code_dim]).
  int64_t restart_dead_codes(const torch::Tensor& usage, const torch::Tensor& z_e, torch::Generator gen);

  int64_t K, code_dim;
  torch::nn::Linear proj_in{nullptr}, proj_out{nullptr};
  torch::nn::Embedding codebook{nullptr};
};
TORCH_MODULE(VectorQuantizer);

}  // namespace gaia::tokenizer
