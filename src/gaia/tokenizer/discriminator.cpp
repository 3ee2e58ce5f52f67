#include "gaia/tokenizer/discriminator.h"

#include "gaia/torch/conv_blocks.h"

namespace gaia::tokenizer {

PatchDiscriminatorImpl::PatchDiscriminatorImpl(const TokenizerConfig& t) {
  using torch::nn::Conv2dOptions;
  int64_t c = t.disc_channels;
  net->push_back(torch::nn::Conv2d(Conv2dOptions(3, c, 4).stride(2).padding(1)));
  net->push_back(torch::nn::LeakyReLU(torch::nn::LeakyReLUOptions().negative_slope(0.2)));
  for (int i = 1; i <= t.disc_layers; ++i) {
    int64_t co = int64_t(t.disc_channels) * std::min(1 << i, 8);
    int64_t stride = i < t.disc_layers ? 2 : 1;
    net->push_back(torch::nn::Conv2d(Conv2dOptions(c, co, 4).stride(stride).padding(1).bias(false)));
    net->push_back(group_norm(co));
    net->push_back(torch::nn::LeakyReLU(torch::nn::LeakyReLUOptions().negative_slope(0.2)));
    c = co;
  }
  net->push_back(torch::nn::Conv2d(Conv2dOptions(c, 1, 4).stride(1).padding(1)));
  register_module("net", net);
}

torch::Tensor PatchDiscriminatorImpl::forward(const torch::Tensor& x) { return net->forward(x); }

torch::Tensor hinge_d_loss(const torch::Tensor& real, const torch::Tensor& fake) {
  return 0.5 * (torch::relu(1.0 - real).mean() + torch::relu(1.0 + fake).mean());
}

torch::Tensor hinge_g_loss(const torch::Tensor& fake) { return -fake.mean(); }

}  // namespace gaia::tokenizer
