#include "gaia/torch/attention.h"

#include <cmath>
#include <limits>
#include <vector>

#include <torch/version.h>

#include "gaia/core/error.h"
#include "gaia/torch/causal_softmax.h"

namespace gaia {

torch::Tensor causal_mask(int64_t Lq, int64_t Lk, int64_t offset, const torch::TensorOptions& options) {
  auto qi = torch::arange(offset, offset + Lq, options.dtype(torch::kLong)).unsqueeze(1);
  auto kj = torch::arange(Lk, options.dtype(torch::kLong)).unsqueeze(0);
  return torch::zeros({Lq, Lk}, options).masked_fill_(kj > qi, -std::numeric_limits<float>::infinity());
}

torch::Tensor attention(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v, const torch::Tensor& bias,
                        bool causal) {
  const int64_t Lq = q.size(-2), Lk = k.size(-2), hd = q.size(-1);
  if (causal && Lq != Lk) fail("attention: a causal mask needs as many queries as keys ({} vs {})", Lq, Lk);
#if TORCH_VERSION_MAJOR >= 2
  if (!bias.defined()) return at::scaled_dot_product_attention(q, k, v, {}, 0.0, causal);
  if (!causal) return at::scaled_dot_product_attention(q, k, v, bias, 0.0, false);
#endif
  const double scale = 1.0 / std::sqrt(double(hd));
  std::vector<int64_t> lead(q.sizes().begin(), q.sizes().end() - 2);
  int64_t n = 1;
  for (auto s : lead) n *= s;
  auto out = lead;
  out.insert(out.end(), {Lq, v.size(-1)});
  auto q3 = q.reshape({n, Lq, hd}), kt = k.transpose(-2, -1).reshape({n, hd, Lk}), v3 = v.reshape({n, Lk, v.size(-1)});
  // Training (a gradient wanted) on the CPU: the causal softmax kernel. Inference keeps one path for every causal
  // attention, whole or block by block, so a rollout's tokens do not depend on how its cache was filled.
  const bool grad = torch::GradMode::is_enabled() && (q.requires_grad() || k.requires_grad() || v.requires_grad());
  torch::Tensor att;  // [n, Lq, Lk], batched 3-D products over the leading dimensions
  if (causal && !bias.defined() && q.device().is_cpu() && grad) {
    auto s = torch::bmm(q3, kt);  // [n, L, L], the scale applied as the softmax reads them
    if (causal_softmax_applies(s)) return torch::bmm(causal_softmax(s, scale).to(v3.scalar_type()), v3).view(out);
    att = s * scale + causal_mask(Lq, Lk, 0, s.options());  // scores the kernel does not take (fp16), kept
  } else {
    torch::Tensor mask = bias;
    if (causal) mask = mask.defined() ? mask + causal_mask(Lq, Lk, 0, q.options()) : causal_mask(Lq, Lk, 0, q.options());
    if (mask.defined() && mask.dim() == 2) {
      att = torch::baddbmm(mask, q3, kt, /*beta=*/1.0, /*alpha=*/scale);  // the mask fused into the product
    } else if (mask.defined()) {
      auto scores = lead;
      scores.insert(scores.end(), {Lq, Lk});
      att = ((torch::bmm(q3, kt) * scale).view(scores) + mask).reshape({n, Lq, Lk});
    } else {
      att = torch::bmm(q3, kt) * scale;
    }
  }
  // Softmax statistics in float32 for bf16 / fp16 scores (autocast), in the scores' own type otherwise.
  const auto t = att.scalar_type();
  const auto stats = t == torch::kBFloat16 || t == torch::kHalf ? torch::kFloat : t;
  return torch::bmm(torch::softmax(att, -1, stats).to(v3.scalar_type()), v3).view(out);
}

}  // namespace gaia
