#include "gaia/tokenizer/augment.h"

namespace gaia::tokenizer {

torch::Tensor darken_some(const torch::Tensor& x, double share) {
  if (share <= 0) return x;
  const int64_t b = x.size(0);
  auto opts = x.options().dtype(torch::kFloat);
  auto pick = torch::rand({b, 1, 1, 1}, opts) < share;             // [B, 1, 1, 1]
  auto gamma = 1 + 2 * torch::rand({b, 1, 1, 1}, opts);             // U(1, 3)
  auto gain = 0.2 + 0.8 * torch::rand({b, 1, 1, 1}, opts);          // U(0.2, 1)
  auto v = ((x.to(torch::kFloat) + 1) / 2).clamp(0, 1);
  auto dark = (gain * v.pow(gamma)) * 2 - 1;
  return torch::where(pick, dark, x.to(torch::kFloat)).to(x.scalar_type());
}

}  // namespace gaia::tokenizer
