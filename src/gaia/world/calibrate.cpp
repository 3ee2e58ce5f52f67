#include "gaia/world/calibrate.h"

#include <cmath>
#include <optional>

#include "gaia/core/error.h"
#include "gaia/world/evaluate.h"

namespace gaia::world {

namespace {
// log p_b(copy) from log p0(copy) = a: a + b - log(1 - e^a + e^(a + b)), computed without cancellation.
// (b a number or a tensor of a's shape)
template <class B>
torch::Tensor log_p_with_bias(const torch::Tensor& a, const B& b) {
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

CopyBias fit_copy_biases(const torch::Tensor& log_p_copy, const torch::Tensor& copied, const torch::Tensor& run) {
  auto a = log_p_copy.to(torch::kDouble).flatten(), y = copied.to(torch::kDouble).flatten();
  auto r = run.to(torch::kBool).flatten();
  if (r.numel() != y.numel())
    fail("fit_copy_biases: need a run flag for every outcome (got {} and {})", r.numel(), y.numel());
  auto fit_where = [&](const torch::Tensor& m) -> std::optional<double> {
    auto ym = y.masked_select(m);
    const double k = ym.sum().item<double>();
    if (k <= 0 || k >= double(ym.numel())) return std::nullopt;
    return fit_copy_bias(a.masked_select(m), ym);
  };
  auto in_run = fit_where(r), out_run = fit_where(~r);
  if (in_run && out_run) return {*out_run, *in_run - *out_run};
  return {fit_copy_bias(a, y), 0.0};
}

CopyCalibration calibrate_copy_bias(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows,
                                    const TextSource& text, const ConditioningMix& mix, int64_t batch,
                                    const std::function<void(int64_t, int64_t)>& progress) {
  torch::NoGradGuard ng;
  model->eval();
  if (windows.empty()) fail("calibrate: no windows");
  if (model->layout.T < 2) fail("calibrate: the context holds one step, so no token has a previous frame in view");
  const auto dev = model->token_embedding->weight.device();
  const CopyBias was = CopyBias::of(model->cfg);
  std::vector<torch::Tensor> logp_copy, logp_true, copied, runs;
  for (size_t w0 = 0; w0 < windows.size(); w0 += size_t(batch)) {
    WorldBatch b = batch_at(ds, windows, w0, batch, text, model->layout.m, mix).to(dev);  // the same fit every time
    auto lp = torch::log_softmax(model->forward(b).slice(1, 1).to(torch::kFloat), -1);  // [B, T-1, n, K]
    auto tok = b.tokens.to(torch::kLong);
    auto prev = tok.slice(1, 0, -1), cur = tok.slice(1, 1);
    auto keep = scored_steps(windows, w0, b.batch(), b.steps(), 1).to(dev);  // [B, T - 1, 1]: frames with a past
    auto run = CopyBias{0, 1}.per_slot(cur, prev) > 0;  // [B, T-1, n]: slot i - 1 kept its code
    auto sel = [&](const torch::Tensor& x) { return x.masked_select(keep.expand_as(x)).to(torch::kCPU); };
    logp_copy.push_back(sel(lp.gather(-1, prev.unsqueeze(-1)).squeeze(-1)));
    logp_true.push_back(sel(lp.gather(-1, cur.unsqueeze(-1)).squeeze(-1)));
    copied.push_back(sel(prev == cur));
    runs.push_back(sel(run));
    if (progress) progress(int64_t(std::min(windows.size(), w0 + size_t(batch))), int64_t(windows.size()));
  }
  auto a = torch::cat(logp_copy).to(torch::kDouble), t = torch::cat(logp_true).to(torch::kDouble);
  auto y = torch::cat(copied).to(torch::kDouble);
  auto r = torch::cat(runs);
  // Under the model's own bias: remove it to get p0 (the bias each token had), then fit the totals.
  auto b0 = torch::where(r, torch::full_like(a, was.at(true)), torch::full_like(a, was.at(false)));
  auto a0 = log_p_with_bias(a, -b0);
  CopyCalibration c;
  c.tokens = y.numel();
  c.copy_rate = c.tokens ? y.mean().item<double>() : 0.0;
  c.fitted = c.copy_rate > 0 && c.copy_rate < 1;
  if (!c.fitted) {
    c.bias = was.bias, c.run = was.run;
    return c;
  }
  const CopyBias now = fit_copy_biases(a0, y, r);
  c.bias = now.bias, c.run = now.run;
  auto b1 = torch::where(r, torch::full_like(a, now.at(true)), torch::full_like(a, now.at(false)));
  c.predicted_before = a.exp().mean().item<double>();
  // Moving a token's bias by d renormalises every code by Z = 1 - p(copy) + p(copy) e^d and raises the copied code by
  // d: log p'(x) = log p(x) + d [x = copy] - log Z.
  auto d = b1 - b0;
  auto logZ = torch::logaddexp(torch::log1p(-a.exp().clamp_max(1 - 1e-12)), a + d);
  c.predicted_after = (a + d - logZ).exp().mean().item<double>();
  c.nats_before = -t.mean().item<double>();
  c.nats_after = -(t + d * y - logZ).mean().item<double>();
  return c;
}

}  // namespace gaia::world
