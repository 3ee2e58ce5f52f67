#pragma once
// Exponential moving average of parameters (§4.3: decay 0.999 for the video decoder).
#include <torch/torch.h>

namespace gaia::train {

// ema <- d * ema + (1 - d) * model, parameter by parameter (same architecture). Returns the d used.
// With warm-up, d = min(decay, (1 + step) / (10 + step)): early averages are not dominated by the random
// initial weights, which matters for short CPU runs (at step 3000 d is 0.997).
double ema_update(torch::nn::Module& ema, const torch::nn::Module& model, double decay, int step, bool warmup = true);

// ema <- model (parameters and buffers).
void ema_copy(torch::nn::Module& ema, const torch::nn::Module& model);

}  // namespace gaia::train
