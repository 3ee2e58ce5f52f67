#pragma once
// Learning-rate schedule used by all three models (paper §4): linear warm-up, then cosine decay to a final rate.
#include <cmath>

namespace gaia::train {

struct WarmupCosine {
  double base_lr = 1e-4, final_lr = 1e-5;
  int warmup = 0, total = 1;

  double operator()(int step) const {
    if (warmup > 0 && step < warmup) return base_lr * (step + 1) / warmup;
    if (total <= warmup) return base_lr;
    double p = std::min(1.0, double(step - warmup) / double(total - warmup));
    return final_lr + 0.5 * (base_lr - final_lr) * (1 + std::cos(M_PI * p));
  }
};

}  // namespace gaia::train
