#pragma once
// Convolutional building blocks (VQGAN-style, Esser et al. 2021) shared by the image tokenizer, the video
// decoder's U-Net and the probes.
#include <torch/torch.h>

namespace gaia {

// GroupNorm with up to 32 groups that divide the width.
torch::nn::GroupNorm group_norm(int64_t channels);

// x [B, cin, H, W] -> [B, cout, H, W]: GN, SiLU, conv3x3, GN, SiLU, conv3x3, plus a 1x1 skip when widths differ.
struct ResBlockImpl : torch::nn::Module {
  ResBlockImpl(int64_t cin, int64_t cout);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::GroupNorm norm1{nullptr}, norm2{nullptr};
  torch::nn::Conv2d conv1{nullptr}, conv2{nullptr}, skip{nullptr};
};
TORCH_MODULE(ResBlock);

// [B, C, H, W] -> [B, C, H/2, W/2]: stride-2 conv3x3.
struct DownsampleImpl : torch::nn::Module {
  explicit DownsampleImpl(int64_t c);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Conv2d conv{nullptr};
};
TORCH_MODULE(Downsample);

// [B, C, H, W] -> [B, C, 2H, 2W]: nearest upsample then conv3x3 (no checkerboard artefacts).
struct UpsampleImpl : torch::nn::Module {
  explicit UpsampleImpl(int64_t c);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Conv2d conv{nullptr};
};
TORCH_MODULE(Upsample);

}  // namespace gaia
