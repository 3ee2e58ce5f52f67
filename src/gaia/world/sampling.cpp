#include "gaia/world/sampling.h"

#include <ATen/CPUGeneratorImpl.h>
#include <ATen/core/DistributionsHelper.h>

#include <algorithm>
#include <limits>
#include <mutex>
#include <numeric>
#include <vector>

#include "gaia/core/error.h"

namespace gaia::world {

Strategy parse_strategy(const std::string& s) {
  if (s == "argmax") return Strategy::Argmax;
  if (s == "sample") return Strategy::Sample;
  if (s == "top-k" || s == "topk") return Strategy::TopK;
  if (s == "top-p" || s == "topp") return Strategy::TopP;
  fail("unknown sampling strategy '{}' (choose argmax, sample, top-k or top-p)", s);
}

std::string to_string(Strategy s) {
  switch (s) {
    case Strategy::Argmax: return "argmax";
    case Strategy::Sample: return "sample";
    case Strategy::TopK: return "top-k";
    case Strategy::TopP: return "top-p";
  }
  return "?";
}

torch::Tensor keep_top_k(const torch::Tensor& logits, const torch::Tensor& ranking, int64_t k) {
  if (k < 1) fail("top_k must be >= 1 (got {})", k);
  if (k >= ranking.size(-1)) return logits;
  auto keep = torch::zeros_like(logits, torch::kBool).scatter_(-1, std::get<1>(ranking.topk(k, -1)), true);
  return logits.masked_fill(~keep, -std::numeric_limits<float>::infinity());
}

torch::Tensor sampling_distribution(const torch::Tensor& logits_in, const SamplingOptions& o) {
  auto logits = logits_in.to(torch::kFloat);
  if (o.strategy == Strategy::Argmax)
    return torch::zeros_like(logits).scatter_(-1, logits.argmax(-1, true), 1.0);
  if (!(o.temperature > 0)) fail("temperature must be > 0 (got {})", o.temperature);
  logits = logits / o.temperature;
  const float neg_inf = -std::numeric_limits<float>::infinity();
  if (o.strategy == Strategy::TopK) {
    logits = keep_top_k(logits, logits, o.top_k);
  } else if (o.strategy == Strategy::TopP) {
    if (!(o.top_p > 0 && o.top_p <= 1)) fail("top_p must be in (0, 1] (got {})", o.top_p);
    auto sorted = logits.sort(-1, /*descending=*/true);
    auto probs = torch::softmax(std::get<0>(sorted), -1);
    auto before = probs.cumsum(-1) - probs;  // mass strictly above each token
    auto drop_sorted = before >= o.top_p;     // keeps the smallest prefix reaching top_p (always >= 1 token)
    auto drop = torch::zeros_like(drop_sorted).scatter_(-1, std::get<1>(sorted), drop_sorted);
    logits = logits.masked_fill(drop, neg_inf);
  }
  return torch::softmax(logits, -1);
}

torch::Tensor sample_tokens(const torch::Tensor& logits, const SamplingOptions& o, torch::Generator& gen) {
  if (o.strategy == Strategy::Argmax) return logits.argmax(-1);
  if (o.strategy == Strategy::TopK && o.top_k >= 1 && o.temperature > 0) {
    // The same distribution as sampling_distribution's, drawn over the k kept logits only: a rollout samples
    // n tokens per frame, and masking all K codes costs several passes over [B, K] per token.
    auto top = logits.to(torch::kFloat).topk(std::min<int64_t>(o.top_k, logits.size(-1)), -1);
    auto p = torch::softmax(std::get<0>(top) / o.temperature, -1).to(torch::kCPU).contiguous();
    auto ids = std::get<1>(top).to(torch::kCPU).contiguous();
    const int64_t B = p.size(0), k = p.size(1);
    auto out = torch::empty({B}, torch::kLong);
    int64_t* chosen = out.data_ptr<int64_t>();
    std::vector<int64_t> order(static_cast<size_t>(k)), sorted_ids(order.size());
    std::vector<float> sorted_p(order.size());
    for (int64_t b = 0; b < B; ++b) {  // the candidates in ascending id order, as draw_token takes them
      const int64_t* id = ids.data_ptr<int64_t>() + b * k;
      const float* pb = p.data_ptr<float>() + b * k;
      std::iota(order.begin(), order.end(), int64_t{0});
      std::sort(order.begin(), order.end(), [&](int64_t x, int64_t y) { return id[x] < id[y]; });
      for (size_t j = 0; j < order.size(); ++j) sorted_ids[j] = id[order[j]], sorted_p[j] = pb[order[j]];
      chosen[b] = draw_token(sorted_ids.data(), sorted_p.data(), k, gen);
    }
    return out.to(logits.device());
  }
  auto p = sampling_distribution(logits, o);
  return torch::multinomial(p.to(torch::kCPU), 1, false, gen).squeeze(-1).to(logits.device());
}

int64_t draw_token(const int64_t* ids, const float* weights, int64_t n, torch::Generator& gen) {
  if (n < 1) fail("draw_token: no candidates");
  double u = 0;
  {
    auto* g = at::check_generator<at::CPUGeneratorImpl>(gen);
    std::lock_guard<std::mutex> lock(g->mutex_);
    u = at::uniform_real_distribution<double>(0.0, 1.0)(g);
  }
  double total = 0;
  for (int64_t j = 0; j < n; ++j) total += double(weights[j]);
  const double target = u * total;
  double cum = 0;
  for (int64_t j = 0; j < n; ++j) {
    cum += double(weights[j]);
    if (target < cum) return ids[j];
  }
  for (int64_t j = n - 1; j > 0; --j)  // u * total rounded up to the sum: the last candidate with weight
    if (weights[j] > 0) return ids[j];
  return ids[0];
}

}  // namespace gaia::world
