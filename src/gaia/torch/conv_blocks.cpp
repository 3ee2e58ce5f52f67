#include "gaia/torch/conv_blocks.h"

namespace gaia {

namespace F = torch::nn::functional;

torch::nn::GroupNorm group_norm(int64_t c) {
  int64_t g = std::min<int64_t>(32, c);
  while (c % g) --g;
  return torch::nn::GroupNorm(torch::nn::GroupNormOptions(g, c).eps(1e-6));
}

ResBlockImpl::ResBlockImpl(int64_t cin, int64_t cout) {
  norm1 = register_module("norm1", group_norm(cin));
  conv1 = register_module("conv1", torch::nn::Conv2d(torch::nn::Conv2dOptions(cin, cout, 3).padding(1)));
  norm2 = register_module("norm2", group_norm(cout));
  conv2 = register_module("conv2", torch::nn::Conv2d(torch::nn::Conv2dOptions(cout, cout, 3).padding(1)));
  if (cin != cout) skip = register_module("skip", torch::nn::Conv2d(torch::nn::Conv2dOptions(cin, cout, 1)));
}

torch::Tensor ResBlockImpl::forward(const torch::Tensor& x) {
  auto h = conv1(F::silu(norm1(x)));
  h = conv2(F::silu(norm2(h)));
  return (skip ? skip(x) : x) + h;
}

DownsampleImpl::DownsampleImpl(int64_t c) {
  conv = register_module("conv", torch::nn::Conv2d(torch::nn::Conv2dOptions(c, c, 3).stride(2).padding(1)));
}

torch::Tensor DownsampleImpl::forward(const torch::Tensor& x) { return conv(x); }

UpsampleImpl::UpsampleImpl(int64_t c) {
  conv = register_module("conv", torch::nn::Conv2d(torch::nn::Conv2dOptions(c, c, 3).padding(1)));
}

torch::Tensor UpsampleImpl::forward(const torch::Tensor& x) {
  return conv(F::interpolate(x, F::InterpolateFuncOptions().scale_factor(std::vector<double>{2, 2}).mode(torch::kNearest)));
}

}  // namespace gaia
