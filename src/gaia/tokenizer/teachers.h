#pragma once
// Frozen teacher networks for the tokenizer losses (§2.2), loaded from safetensors in the public layouts:
//  - VGG16 `features` (torchvision layout: features.0.weight ... features.28.bias) for the perceptual loss
//    (Johnson et al. 2016). Channel widths are read from the file, so a width-reduced VGG16 fixture runs the same code.
//  - a DINO ViT (timm layout: patch_embed.proj, cls_token, pos_embed, blocks.N.{norm1,attn.qkv,attn.proj,norm2,
//    mlp.fc1,mlp.fc2}, norm), or torchvision's VisionTransformer layout (mapped on load), for the inductive-bias loss.
// A teacher not given switches the corresponding loss off and the trainer logs that plainly; a teacher file that is
// named but missing or in another layout is an error naming it.
#include <torch/torch.h>

#include "gaia/core/fs.h"

namespace gaia::tokenizer {

struct Vgg16Impl : torch::nn::Module {
  explicit Vgg16Impl(const fs::path& weights);  // throws naming the file on missing/mismatched tensors
  // x [B, 3, H, W] in [-1, 1] -> activations after relu1_2, relu2_2, relu3_3, relu4_3, relu5_3.
  std::vector<torch::Tensor> forward(const torch::Tensor& x);
  torch::nn::Sequential features;
};
TORCH_MODULE(Vgg16);

// Perceptual distance: mean over layers of the squared difference of channel-normalised VGG activations.
torch::Tensor perceptual_loss(Vgg16& vgg, const torch::Tensor& x, const torch::Tensor& y);

struct ViTBlockImpl : torch::nn::Module {
  ViTBlockImpl(int64_t dim, int64_t heads, int64_t mlp_dim);
  torch::Tensor forward(const torch::Tensor& x);  // [B, N, D] -> [B, N, D]
  int64_t heads;
  torch::nn::LayerNorm norm1{nullptr}, norm2{nullptr};
  torch::nn::Linear qkv{nullptr}, proj{nullptr}, fc1{nullptr}, fc2{nullptr};
};
TORCH_MODULE(ViTBlock);

struct DinoViTImpl : torch::nn::Module {
  explicit DinoViTImpl(const fs::path& weights);  // timm or torchvision layout; heads from metadata or dim / 64
  // x [B, 3, H, W] in [-1, 1] (ImageNet-normalised inside) -> patch features [B, D, H/p, W/p] after the final norm.
  torch::Tensor forward(const torch::Tensor& x);
  int64_t dim = 0, patch = 0, heads = 0, grid = 0;  // grid: side of the pretraining patch grid (pos_embed)
  torch::nn::Conv2d patch_embed{nullptr};
  torch::Tensor cls_token, pos_embed;
  torch::nn::ModuleList blocks;
  torch::nn::LayerNorm norm{nullptr};
};
TORCH_MODULE(DinoViT);

// [-1, 1] RGB -> ImageNet mean/std normalisation expected by both teachers.
torch::Tensor imagenet_normalize(const torch::Tensor& x);

}  // namespace gaia::tokenizer
