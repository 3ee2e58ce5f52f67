#include "gaia/world/calibrate.h"

#include <cmath>

#include "gaia/core/error.h"
#include "gaia/world/evaluate.h"

namespace gaia::world {

namespace {
// log p_b(copy) from log p0(copy) = a: a + b - log(1 - e^a + e^(a + b)), computed without cancellation.
torch::Tensor log_p_with_bias(const torch::Tensor& a, double b) {
  return a + b - torch::logaddexp(torch::log1p(-a.exp().clamp_max(1 - 1e-12)), a + b);
}
}  // namespace

double fit_copy_bias(const torch::Tensor& log_p_copy, const torch::Tensor& copied) {
  auto a = log_p_copy.to(torch::kDouble).flatten();
  auto y = copied.to(torch::kDouble).flatten();
  if (a.numel() == 0 || a.numel() != y.numel()) fail("fit_copy_bias: need as many probabilities as outcomes (got {} and {})", a.numel(), y.numel());
  const double target = y.sum().item<double>();
  if (target <= 0 || target >= double(y.numel()))
    fail("fit_copy_bias: {} of {} tokens were copied; the bias has no finite optimum", target, y.numel());
  // sum_i p_b,i rises monotonically in b: bisection to the b where it equals the number of copies.
  double lo = -30, hi = 30;
  for (int it = 0; it < 100; ++it) {
    const double mid = (lo + hi) / 2;
    (log_p_with_bias(a, mid).exp().sum().item<double>() < target ? lo : hi) = mid;
  }
  return (lo + hi) / 2;
}

CopyCalibration calibrate_copy_bias(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows,
                                    const TextSource& text, const ConditioningMix& mix, int64_t batch,
                                    const std::function<void(int64_t, int64_t)>& progress) {
  torch::NoGradGuard ng;
  model->eval();
  if (windows.empty()) fail("calibrate: no windows");
  if (model->layout.T < 2) fail("calibrate: the context holds one step, so no token has a previous frame in view");
  const auto dev = model->token_embedding->weight.device();
  const double b0 = model->cfg.copy_bias;
  std::vector<torch::Tensor> logp_copy, logp_true, copied;
  for (size_t w0 = 0; w0 < windows.size(); w0 += size_t(batch)) {
    WorldBatch b = batch_at(ds, windows, w0, batch, text, model->layout.m, mix).to(dev);  // the same fit every time
    auto lp = torch::log_softmax(model->forward(b).slice(1, 1).to(torch::kFloat), -1);  // [B, T-1, n, K]
    auto tok = b.tokens.to(torch::kLong);
    auto prev = tok.slice(1, 0, -1).unsqueeze(-1), cur = tok.slice(1, 1).unsqueeze(-1);
    logp_copy.push_back(lp.gather(-1, prev).flatten().to(torch::kCPU));
    logp_true.push_back(lp.gather(-1, cur).flatten().to(torch::kCPU));
    copied.push_back((prev == cur).flatten().to(torch::kCPU));
    if (progress) progress(int64_t(std::min(windows.size(), w0 + size_t(batch))), int64_t(windows.size()));
  }
  auto a = torch::cat(logp_copy).to(torch::kDouble), t = torch::cat(logp_true).to(torch::kDouble);
  auto y = torch::cat(copied).to(torch::kDouble);
  // Under b0 the model already had its own bias: remove it to get p0, then fit the total.
  auto a0 = log_p_with_bias(a, -b0);
  CopyCalibration c;
  c.tokens = y.numel();
  c.copy_rate = y.mean().item<double>();
  c.fitted = c.copy_rate > 0 && c.copy_rate < 1;
  c.bias = c.fitted ? fit_copy_bias(a0, y) : b0;
  c.predicted_before = a.exp().mean().item<double>();
  // Moving the bias by d renormalises every code by Z = 1 - p(copy) + p(copy) e^d and raises the copied code by d:
  // log p'(x) = log p(x) + d [x = copy] - log Z.
  const double d = c.bias - b0;
  auto logZ = torch::logaddexp(torch::log1p(-a.exp().clamp_max(1 - 1e-12)), a + d);
  c.predicted_after = (a + d - logZ).exp().mean().item<double>();
  c.nats_before = -t.mean().item<double>();
  c.nats_after = -(t + d * y - logZ).mean().item<double>();
  return c;
}

}  // namespace gaia::world
