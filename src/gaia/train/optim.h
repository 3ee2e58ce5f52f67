#pragma once
// AdamW with the paper's settings per model, learning-rate updates, gradient clipping.
#include <torch/torch.h>

namespace gaia::train {

// AdamW over the given parameters; biases and norm gains (1-D tensors) get no weight decay, as in nanoGPT.
std::unique_ptr<torch::optim::AdamW> make_adamw(const std::vector<torch::Tensor>& params, double lr, double weight_decay,
                                                double beta1, double beta2);
void set_lr(torch::optim::Optimizer& opt, double lr);
// Clips the global gradient norm; returns the norm before clipping (NaN/inf means a bad step).
double clip_grad_norm(const std::vector<torch::Tensor>& params, double max_norm);

}  // namespace gaia::train
