#include "gaia/train/ema.h"

#include <algorithm>

#include "gaia/core/error.h"

namespace gaia::train {

double ema_update(torch::nn::Module& ema, const torch::nn::Module& model, double decay, int step, bool warmup) {
  torch::NoGradGuard ng;
  const double d = warmup ? std::min(decay, (1.0 + step) / (10.0 + step)) : decay;
  auto e = ema.parameters(), p = model.parameters();
  if (e.size() != p.size()) fail("EMA: the averaged model has {} parameters, the trained one {}", e.size(), p.size());
  for (size_t i = 0; i < e.size(); ++i) e[i].mul_(d).add_(p[i].detach(), 1.0 - d);
  return d;
}

void ema_copy(torch::nn::Module& ema, const torch::nn::Module& model) {
  torch::NoGradGuard ng;
  auto e = ema.parameters(), p = model.parameters();
  if (e.size() != p.size()) fail("EMA: the averaged model has {} parameters, the trained one {}", e.size(), p.size());
  for (size_t i = 0; i < e.size(); ++i) e[i].copy_(p[i]);
  auto eb = ema.buffers(), pb = model.buffers();
  for (size_t i = 0; i < std::min(eb.size(), pb.size()); ++i) eb[i].copy_(pb[i]);
}

}  // namespace gaia::train
