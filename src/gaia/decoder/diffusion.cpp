#include "gaia/decoder/diffusion.h"

#include <cmath>

namespace gaia::decoder {

torch::Tensor NoiseSchedule::logsnr(const torch::Tensor& t) const {
  // tan(pi t / 2) is 0 at t = 0 (logsnr -> +inf) and inf at t = 1 (logsnr -> -inf): clip to the finite range.
  auto tt = t.to(torch::kFloat64).clamp(1e-9, 1.0 - 1e-9);
  auto l = -2.0 * torch::log(torch::tan(tt * (M_PI / 2))) + 2.0 * std::log(shift);
  return l.clamp(logsnr_min, logsnr_max).to(t.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32);
}

torch::Tensor v_loss(const torch::Tensor& v_pred, const torch::Tensor& v_true, const torch::Tensor& weight,
                     double w_l1, double w_l2) {
  // [B, T, C, H, W]: mean over C, H, W per frame, then a weighted mean over the frames that are predicted.
  auto d = v_pred - v_true;
  auto l1 = d.abs().flatten(2).mean(-1);   // [B, T]
  auto l2 = d.pow(2).flatten(2).mean(-1);  // [B, T]
  auto w = weight.to(v_pred.dtype());
  auto denom = w.sum().clamp_min(1.0);
  return (w * (w_l1 * l1 + w_l2 * l2)).sum() / denom;
}

torch::Tensor temporal_v_loss(const torch::Tensor& v_pred, const torch::Tensor& v_true, const torch::Tensor& weight) {
  auto e = v_pred - v_true;                                                        // [B, T, C, H, W]
  auto de = (e.slice(1, 1) - e.slice(1, 0, -1)).abs().flatten(2).mean(-1);         // [B, T - 1]
  auto w = weight.to(v_pred.dtype());
  auto pair = (w.slice(1, 1) > 0).logical_and(w.slice(1, 0, -1) > 0).to(v_pred.dtype());  // [B, T - 1]
  return (pair * de).sum() / pair.sum().clamp_min(1.0);
}

torch::Tensor ddim_step(const torch::Tensor& xt, const torch::Tensor& v, const torch::Tensor& alpha_t,
                        const torch::Tensor& sigma_t, const torch::Tensor& alpha_s, const torch::Tensor& sigma_s) {
  auto x_hat = x_from_v(xt, v, alpha_t, sigma_t);
  auto eps_hat = eps_from_v(xt, v, alpha_t, sigma_t);
  return alpha_s * x_hat + sigma_s * eps_hat;
}

torch::Tensor interpolation_base(const torch::Tensor& cond_image, const torch::Tensor& frames,
                                 const torch::Tensor& context, const torch::Tensor& has_tokens) {
  const int64_t B = frames.size(0), T = frames.size(1);
  auto out = cond_image.clone();
  auto ctx = context.to(torch::kCPU).to(torch::kFloat32).contiguous();
  auto tok = has_tokens.to(torch::kCPU).to(torch::kBool).contiguous();
  auto c = ctx.accessor<float, 2>();
  auto k = tok.accessor<bool, 2>();
  for (int64_t b = 0; b < B; ++b)
    for (int64_t t = 0; t < T; ++t) {
      if (c[b][t] > 0.5f || k[b][t]) continue;
      int64_t l = t - 1, r = t + 1;  // nearest context frames on each side
      while (l >= 0 && c[b][l] <= 0.5f) --l;
      while (r < T && c[b][r] <= 0.5f) ++r;
      auto dst = out[b][t];
      if (l >= 0 && r < T) {
        const double w = double(t - l) / double(r - l);
        dst.copy_((1 - w) * frames[b][l] + w * frames[b][r]);
      } else if (l >= 0 || r < T) {
        dst.copy_(frames[b][l >= 0 ? l : r]);
      }
    }
  return out;
}

std::vector<double> ddim_times(int steps, double start) {
  std::vector<double> t(size_t(steps) + 1);
  for (int i = 0; i <= steps; ++i) t[size_t(i)] = start * (1.0 - double(i) / steps);
  return t;
}

}  // namespace gaia::decoder
