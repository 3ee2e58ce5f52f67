#include "gaia/world/rollout.h"

#include <chrono>

#include "gaia/core/error.h"
#include "gaia/world/batch.h"

namespace gaia::world {

namespace {

// Step conditioning for rows [cond x N | uncond x N] (or just cond x N) over global steps [k0, k1).
struct Conditioner {
  const RolloutPrompt& p;
  int64_t N;
  bool guided;
  torch::Device dev;

  // per_step is [P + F, ...] shared by all futures, or [N, P + F, ...] one row per future (one more dimension than
  // the shared form's `base_dims`) -> [B, k1 - k0, ...]; the uncond half uses `uncond` when defined, else a copy.
  torch::Tensor rows(const torch::Tensor& per_step, int64_t base_dims, int64_t k0, int64_t k1,
                     const torch::Tensor& uncond) const {
    auto pick = [&](const torch::Tensor& t) {
      if (t.dim() == base_dims + 1) return t.narrow(1, k0, k1 - k0);
      auto s = t.narrow(0, k0, k1 - k0).unsqueeze(0);
      std::vector<int64_t> rep(static_cast<size_t>(s.dim()), 1);
      rep[0] = N;
      return s.repeat(rep);
    };
    auto c = pick(per_step);
    if (!guided) return c.to(dev);
    auto u = uncond.defined() ? pick(uncond) : c;
    return torch::cat({c, u}, 0).to(dev);
  }

  WorldBatch at(int64_t k0, int64_t k1, const torch::Tensor& tokens) const {
    WorldBatch b;
    b.tokens = tokens;
    const int64_t B = guided ? 2 * N : N;
    auto cond_rows = torch::arange(B) < N;  // [B] true for the conditional half
    if (p.actions.defined()) {
      b.actions = rows(p.actions, 2, k0, k1, p.negative_actions);
      b.use_action = (p.negative_actions.defined() ? torch::ones({B}, torch::kBool) : cond_rows).to(dev);
    }
    const bool neg = p.negative_text_ids.defined() || p.negative_text_emb.defined();
    if (p.text_emb.defined() || p.negative_text_emb.defined()) {
      auto base = p.text_emb.defined() ? p.text_emb : torch::zeros_like(p.negative_text_emb);
      b.text_emb = rows(base, 3, k0, k1, p.negative_text_emb);
    } else if (p.text_ids.defined() || p.negative_text_ids.defined()) {
      auto base = p.text_ids.defined() ? p.text_ids : torch::zeros_like(p.negative_text_ids);
      b.text_ids = rows(base, 2, k0, k1, p.negative_text_ids);
    }
    if (b.text_emb.defined() || b.text_ids.defined()) {
      // cond rows see the prompt text (null if there is none); uncond rows the negative prompt (null if none).
      const bool has_pos = p.text_emb.defined() || p.text_ids.defined();
      b.use_text = torch::cat({torch::full({N}, has_pos), torch::full({B - N}, neg)}).to(torch::kBool).to(dev);
    }
    return b;
  }
};

void check_prompt(const WorldModelImpl& m, const RolloutPrompt& p, int64_t N, int64_t P, int64_t steps) {
  const auto& L = m.layout;
  if (p.tokens.defined() && p.tokens.numel() > 0) {
    const bool per_future = p.tokens.dim() == 3;
    if ((p.tokens.dim() != 2 && !per_future) || p.tokens.size(-1) != L.n || (per_future && p.tokens.size(0) != N))
      fail("prompt tokens must be [frames, n = {}] or [futures = {}, frames, n] (got {} dims, {} per frame)", L.n, N,
           p.tokens.dim(), p.tokens.size(-1));
    if (p.tokens.min().item<int64_t>() < 0 || p.tokens.max().item<int64_t>() >= m.K)
      fail("prompt tokens must be in [0, K = {}) (found {}..{})", m.K, p.tokens.min().item<int64_t>(),
           p.tokens.max().item<int64_t>());
  }
  if (P > L.T) fail("the prompt has {} frames but the context holds {} steps (world.context_steps)", P, L.T);
  // Shared [steps, width, ...] (base_dims dimensions) or per future [N, steps, width, ...].
  auto rows_ok = [&](const torch::Tensor& t, const char* what, int64_t base_dims, int64_t width) {
    if (!t.defined()) return;
    const int64_t o = t.dim() == base_dims + 1 ? 1 : 0;
    if (t.dim() != base_dims + o || (o && t.size(0) != N))
      fail("{} must be [steps, ...] or [futures = {}, steps, ...] with {} dimensions per future (got {} dims)", what, N,
           base_dims, t.dim());
    if (t.size(o) != steps || (width > 0 && t.size(o + 1) != width))
      fail("{} has {} rows of {} but the rollout needs {} rows (prompt + generated frames) of {}", what, t.size(o),
           t.size(o + 1), steps, width);
  };
  rows_ok(p.actions, "actions", 2, 2);
  rows_ok(p.negative_actions, "negative actions", 2, 2);
  if (p.negative_actions.defined() && !p.actions.defined()) fail("rollout: negative actions need actions");
  rows_ok(p.text_ids, "text ids", 2, L.m);
  rows_ok(p.text_emb, "text embeddings", 3, L.m);
  rows_ok(p.negative_text_ids, "negative text ids", 2, L.m);
  rows_ok(p.negative_text_emb, "negative text embeddings", 3, L.m);
}

}  // namespace

torch::Tensor counter_actions(const torch::Tensor& actions, int64_t from, const torch::Tensor& kept_speed) {
  auto m = actions.clone();
  const int64_t d = m.dim() - 2;  // the steps dimension
  if (d < 0 || m.size(-1) != 2 || from < 0 || from > m.size(d))
    fail("counter_actions: need [steps, 2] or [futures, steps, 2] actions and a step within them");
  auto tail = m.narrow(d, from, m.size(d) - from);
  tail.select(-1, 1).mul_(-1);
  if (kept_speed.defined()) {  // [] or [N], broadcast over the steps
    auto v = kept_speed.to(m.dtype()) / kSpeedScale;
    tail.select(-1, 0).copy_(v.dim() == 0 ? v : v.unsqueeze(-1));
  }
  return m;
}

RolloutResult rollout(WorldModel& model, const RolloutPrompt& prompt, const RolloutOptions& o,
                      const std::function<void(int, int)>& on_frame) {
  auto t_start = std::chrono::steady_clock::now();
  torch::NoGradGuard ng;
  model->eval();
  const auto& L = model->layout;
  const bool has_prompt = prompt.tokens.defined() && prompt.tokens.numel() > 0;
  const int64_t P = has_prompt ? prompt.tokens.size(-2) : 0, F = o.frames, steps = P + F;
  if (F < 0 || o.futures < 1) fail("rollout needs frames >= 0 and futures >= 1 (got {} and {})", F, o.futures);
  if (o.window_stride < 1 || o.window_stride >= L.T)
    fail("window stride must be in [1, T - 1 = {}] (got {})", L.T - 1, o.window_stride);
  check_prompt(*model, prompt, o.futures, P, steps);
  const torch::Device dev = model->token_embedding->weight.device();
  const int64_t N = o.futures;
  const bool guided = o.guidance.active();
  const int64_t B = guided ? 2 * N : N, n = L.n, d = model->d;
  Conditioner cond{prompt, N, guided, dev};
  const bool text_guided = prompt.text_ids.defined() || prompt.text_emb.defined() ||
                           prompt.negative_text_ids.defined() || prompt.negative_text_emb.defined();
  const bool within = guided && !text_guided && o.sampling.guide_actions_within_top_k &&
                      o.sampling.strategy == Strategy::TopK;  // SamplingOptions::guide_actions_within_top_k
  auto gen = at::detail::createCPUGenerator(o.seed);

  auto all = torch::zeros({B, steps, n}, torch::TensorOptions().dtype(torch::kLong).device(dev));
  if (P > 0) {
    auto pt = prompt.tokens.to(dev).to(torch::kLong);
    if (pt.dim() == 3) all.narrow(1, 0, P).copy_(guided ? torch::cat({pt, pt}) : pt);  // one prompt per future
    else all.narrow(1, 0, P).copy_(pt.unsqueeze(0).expand({B, P, n}));
  }
  KVCache cache = model->make_cache(B, L.length());
  int64_t win = 0;      // steps in the cache; the current step sits at temporal position `win`
  int64_t first = 0;    // global index of the cache's first step
  for (int64_t k = 0; k < steps; ++k) {
    if (win == L.T) {
      // Sliding window: keep the last T - stride steps, re-embedded at temporal positions 0..T-stride-1.
      first = k - (L.T - o.window_stride);
      cache.reset();
      auto hist = cond.at(first, k, all.narrow(1, first, k - first));
      model->body(model->embed(hist, 0), &cache);
      win = L.T - o.window_stride;
    }
    if (k < P) {  // a prompt frame: the whole step at once
      model->body(model->embed(cond.at(k, k + 1, all.narrow(1, k, 1)), win), &cache);
      ++win;
      continue;
    }
    auto sb = cond.at(k, k + 1, all.narrow(1, k, 1));
    auto h = model->body(model->embed_text(sb, win).view({B, L.m, d}), &cache);
    auto last = h.select(1, h.size(1) - 1);  // [B, d]
    for (int64_t i = 0; i < n; ++i) {
      auto lg = model->logits(last).to(torch::kFloat);  // [B, K]; guidance and sampling in float32 under autocast
      if (k > 0 && model->cfg.copy_bias != 0)  // as in WorldModelImpl::forward
        lg = with_copy_bias(lg, all.select(1, k - 1).select(1, i), model->cfg.copy_bias);
      torch::Tensor tok;
      if (guided) {
        auto c = lg.narrow(0, 0, N);
        auto l = guide(c, lg.narrow(0, N, N), o.guidance.at(int(k - P), int(i), int(n)));
        if (within) l = keep_top_k(l, c, o.sampling.top_k);
        tok = sample_tokens(l, o.sampling, gen);
        tok = torch::cat({tok, tok});  // both halves continue from the same chosen token
      } else {
        tok = sample_tokens(lg, o.sampling, gen);
      }
      all.select(1, k).select(1, i).copy_(tok);
      h = model->body(model->embed_image(tok.view({B, 1, 1}), win, i).view({B, 1, d}), &cache);
      last = h.select(1, 0);
    }
    model->body(model->embed_actions(sb, win).view({B, L.l, d}), &cache);
    ++win;
    if (on_frame) on_frame(int(k - P + 1), int(F));
  }
  RolloutResult r;
  r.tokens = all.narrow(0, 0, N).to(torch::kCPU);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return r;
}

}  // namespace gaia::world
