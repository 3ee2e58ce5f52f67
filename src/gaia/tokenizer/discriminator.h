#pragma once
// PatchGAN discriminator (Isola et al. 2017) for the GAN term of the tokenizer loss (§2.2; Esser et al. 2021), trained
// with the hinge loss. x [B, 3, H, W] -> logits [B, 1, h', w'], one per overlapping patch.
#include <torch/torch.h>

#include "gaia/config.h"

namespace gaia::tokenizer {

struct PatchDiscriminatorImpl : torch::nn::Module {
  explicit PatchDiscriminatorImpl(const TokenizerConfig& c);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Sequential net;
};
TORCH_MODULE(PatchDiscriminator);

torch::Tensor hinge_d_loss(const torch::Tensor& logits_real, const torch::Tensor& logits_fake);
torch::Tensor hinge_g_loss(const torch::Tensor& logits_fake);

}  // namespace gaia::tokenizer
