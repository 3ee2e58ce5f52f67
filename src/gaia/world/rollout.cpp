#include "gaia/world/rollout.h"

#include <algorithm>
#include <chrono>

#if defined(__linux__)
#include <pthread.h>
#endif

#include <ATen/Parallel.h>

#include "gaia/core/error.h"
#include "gaia/world/batch.h"
#include "gaia/world/token_choice.h"

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

RolloutStepper::RolloutStepper(WorldModel& model, const RolloutOptions& o, int64_t futures)
    : model_(model), o_(o), N_(futures), guided_(o.guidance.active()),
      dev_(model->token_embedding->weight.device()), gen_(at::detail::createCPUGenerator(o.seed)) {
  if (futures < 1) fail("rollout needs futures >= 1 (got {})", futures);
  if (o.window_stride < 1 || o.window_stride >= model->layout.T)
    fail("window stride must be in [1, T - 1 = {}] (got {})", model->layout.T - 1, o.window_stride);
  const int64_t B = guided_ ? 2 * N_ : N_;
  cache_ = new_cache(B);
  if (o.fused_tokens && TokenStep::applies(*model, B)) fast_ = std::make_shared<const TokenStep>(*model);
  tokens_ = torch::zeros({B, 8, model->layout.n}, torch::TensorOptions().dtype(torch::kLong).device(dev_));
}

KVCache RolloutStepper::new_cache(int64_t rows) const {
  // Under bf16 on the CPU the keys and values are kept as bf16: the history's come out of bf16 products anyway, and
  // sampling reads the whole cache for every token, so half the bytes is what its attention waits on.
  const bool bf16 = o_.precision == Precision::kBf16 && dev_.is_cpu();
  return model_->make_cache(rows, model_->layout.length(),
                            bf16 ? c10::optional<torch::ScalarType>(torch::kBFloat16) : c10::nullopt);
}

torch::Tensor RolloutStepper::step(const RolloutPrompt& p, const torch::Tensor& given) {
  torch::NoGradGuard ng;
  Autocast autocast(o_.precision, dev_);  // on whichever thread steps (a session's), as the lookahead's below
  model_->eval();
  const auto& L = model_->layout;
  const int64_t B = guided_ ? 2 * N_ : N_, n = L.n, d = model_->d, k = k_;
  Conditioner cond{p, N_, guided_, dev_};
  if (k >= tokens_.size(1)) {  // room for twice as many steps
    auto grown = torch::zeros({B, 2 * tokens_.size(1), n}, tokens_.options());
    grown.narrow(1, 0, k).copy_(tokens_.narrow(1, 0, k));
    tokens_ = grown;
  }
  if (win_ == L.T) {
    // Sliding window: keep the last T - stride steps, re-embedded at temporal positions 0..T-stride-1.
    const int64_t first = k - (L.T - o_.window_stride);
    if (ahead_.first == first && ahead_.job.valid()) {  // encoded on the second thread during the last step
      ahead_.job.get();
      std::swap(cache_, ahead_.cache);
      cache_.length = (L.T - 1) * L.per_step();
    } else {
      cache_.reset();
      auto hist = cond.at(first, k, tokens_.narrow(1, first, k - first));
      model_->prefill(model_->embed(hist, 0), cache_);
    }
    ahead_.job = {};
    ahead_.first = -1;
    win_ = L.T - o_.window_stride;
  }
  ++k_;
  if (given.defined()) {  // a prompt frame: the whole step at once
    auto g = given.to(dev_).to(torch::kLong).view({-1, n});
    if (g.size(0) == 1) g = g.expand({B, n});
    else if (g.size(0) == N_ && guided_) g = torch::cat({g, g});
    if (g.size(0) != B) fail("a prompt frame must be [n] or [futures = {}, n] tokens (got {} rows)", N_, g.size(0));
    tokens_.select(1, k).copy_(g);
    model_->prefill(model_->embed(cond.at(k, k + 1, tokens_.narrow(1, k, 1)), win_), cache_);
    ++win_;
    return tokens_.select(1, k).narrow(0, 0, N_);
  }
  const bool text_guided = p.text_ids.defined() || p.text_emb.defined() || p.negative_text_ids.defined() ||
                           p.negative_text_emb.defined();
  const bool within = guided_ && !text_guided && o_.sampling.guide_actions_within_top_k &&
                      o_.sampling.strategy == Strategy::TopK;  // SamplingOptions::guide_actions_within_top_k
  std::shared_ptr<Lookahead::Progress> progress;
  if (o_.lookahead && fast_ && o_.window_stride == 1 && win_ == L.T - 1 && k >= L.T - 2 &&
      at::get_num_threads() == 1) {
    // The next step slides: encode its history on a second thread now, steps k - T + 2 .. k - 1 at once, then this
    // step's tokens in fixed chunks as they are sampled (fixed, so that the numbers never depend on timing).
    const int64_t first = k - (L.T - 2), t = L.T - 2;
    if (ahead_.cache.k.empty()) ahead_.cache = new_cache(B);
    // The job's own copies: the caller may change its prompt's tensors once this step returns.
    auto own = [](WorldBatch b) {
      for (auto* f : {&b.tokens, &b.actions, &b.text_ids, &b.text_emb, &b.use_action, &b.use_text})
        if (f->defined()) *f = f->clone();
      return b;
    };
    auto hist = own(cond.at(first, k, tokens_.narrow(1, first, k - first)));
    auto now = own(cond.at(k, k + 1, tokens_.narrow(1, k, 1)));  // its text and actions (tokens: filled below)
    if (ahead_.job.valid()) ahead_.job.wait();  // an abandoned job may still hold the cache
    progress = std::make_shared<Lookahead::Progress>(n);
    auto model = model_;
    auto cache = ahead_.cache;  // shares the tensors; the length is set when the result is taken
    auto row = tokens_.select(1, k);  // [B, n], written token by token by this thread
    ahead_.first = first;
    const Precision precision = o_.precision;
    ahead_.job = std::async(std::launch::async, [model, hist, now, cache, row, progress, t, n, B, d,
                                                 precision]() mutable {
#if defined(__linux__)
                   pthread_setname_np(pthread_self(), "gaia-lookahead");  // apart in top -H and perf --sort comm
#endif
                   torch::NoGradGuard ng;
                   Autocast autocast(precision, torch::kCPU);
                   cache.reset();
                   model->prefill(model->embed(hist, 0), cache);
                   for (int64_t a = 0; a < n; a += Lookahead::kChunk) {
                     const int64_t b = std::min(n, a + Lookahead::kChunk);
                     if (!progress->wait_for(b)) return;  // the step failed: the result is not taken
                     std::vector<torch::Tensor> parts;
                     if (a == 0) parts.push_back(model->embed_text(now, t));
                     parts.push_back(model->embed_image(row.narrow(1, a, b - a).clone().unsqueeze(1), t, a));
                     if (b == n) parts.push_back(model->embed_actions(now, t));
                     model->prefill(torch::cat(parts, 2).view({B, -1, d}), cache);
                   }
                 }).share();
  }
  // Until every token is out, a failure leaves the lookahead unused (and its job released).
  struct Release {
    std::shared_ptr<Lookahead::Progress> p;
    Lookahead& ahead;
    ~Release() {
      if (p && !p->done()) {
        p->abandon();
        ahead.first = -1;
      }
    }
  } release{progress, ahead_};
  auto sb = cond.at(k, k + 1, tokens_.narrow(1, k, 1));
  auto h = model_->body(model_->embed_text(sb, win_).view({B, L.m, d}), &cache_);
  auto next = model_->logits(h.select(1, h.size(1) - 1));  // [B, K] predicting z_0
  const bool fast = fast_ && TokenStep::applies(*model_, B);
  // With the fused step, each token is chosen on raw memory too (token_choice.h): the same tokens up to rounding.
  const bool raw = fast && TokenChoice::applies(o_.sampling);
  const TokenChoice choose{o_.sampling, guided_, within};
  int64_t* all = raw ? tokens_.data_ptr<int64_t>() : nullptr;  // [B, capacity, n], contiguous (CPU)
  const int64_t cap = tokens_.size(1);
  auto raw_tok = torch::empty({B}, torch::kLong);
  int64_t prev[TokenStep::kMaxRows];
  float bias[TokenStep::kMaxRows];
  const CopyBias copy = CopyBias::of(model_->cfg);
  const bool biased = k > 0 && copy.any();  // as in WorldModelImpl::forward
  for (int64_t i = 0; i < n; ++i) {
    if (raw) {
      int64_t* t = raw_tok.data_ptr<int64_t>();
      auto lg = next.to(torch::kFloat).contiguous();  // [B, K]
      for (int64_t b = 0; biased && b < B; ++b) {
        const int64_t* now = all + (b * cap + k) * n;
        prev[b] = now[i - n];
        bias[b] = float(copy.at(i > 0 && now[i - 1] == now[i - 1 - n]));
      }
      const double s = guided_ ? o_.guidance.at(int(generated_), int(i), int(n)) : 0.0;
      choose(lg.data_ptr<float>(), N_, model_->K, biased ? prev : nullptr, biased ? bias : nullptr, s, gen_, t);
      for (int64_t b = N_; b < B; ++b) t[b] = t[b - N_];  // both halves continue from the same chosen token
      for (int64_t b = 0; b < B; ++b) all[(b * cap + k) * n + i] = t[b];
      if (progress && ((i + 1) % Lookahead::kChunk == 0 || i + 1 == n)) progress->release(i + 1);
      next = fast_->logits(raw_tok, win_, i, cache_);
      continue;
    }
    auto lg = next.to(torch::kFloat);  // [B, K]; guidance and sampling in float32 under autocast
    if (biased) {  // slot i's bias depends on slot i - 1 only, which is sampled
      const int64_t a = std::max<int64_t>(0, i - 1);
      auto now = tokens_.select(1, k).narrow(1, a, i + 1 - a);
      auto before = tokens_.select(1, k - 1).narrow(1, a, i + 1 - a);
      lg = with_copy_bias(lg, before.select(1, i - a), copy.per_slot(now, before).select(1, i - a));
    }
    torch::Tensor tok;
    if (guided_) {
      auto c = lg.narrow(0, 0, N_);
      auto l = guide(c, lg.narrow(0, N_, N_), o_.guidance.at(int(generated_), int(i), int(n)));
      if (within) l = keep_top_k(l, c, o_.sampling.top_k);
      tok = sample_tokens(l, o_.sampling, gen_);
      tok = torch::cat({tok, tok});  // both halves continue from the same chosen token
    } else {
      tok = sample_tokens(lg, o_.sampling, gen_);
    }
    tokens_.select(1, k).select(1, i).copy_(tok);
    if (progress && ((i + 1) % Lookahead::kChunk == 0 || i + 1 == n)) progress->release(i + 1);
    if (fast) {
      next = fast_->logits(tok, win_, i, cache_);
    } else {
      h = model_->body(model_->embed_image(tok.view({B, 1, 1}), win_, i).view({B, 1, d}), &cache_);
      if (i + 1 < n) next = model_->logits(h.select(1, 0));
    }
  }
  model_->prefill(model_->embed_actions(sb, win_).view({B, L.l, d}), cache_);
  ++win_;
  ++generated_;
  return tokens_.select(1, k).narrow(0, 0, N_);
}

torch::Tensor RolloutStepper::tokens() const { return tokens_.narrow(0, 0, N_).narrow(1, 0, k_); }

bool RolloutStepper::Lookahead::Progress::wait_for(int64_t tokens) {
  std::unique_lock<std::mutex> lock(m);
  cv.wait(lock, [&] { return sampled >= tokens || abandoned; });
  return !abandoned;
}

void RolloutStepper::Lookahead::Progress::release(int64_t tokens) {
  {
    std::lock_guard<std::mutex> lock(m);
    sampled = tokens;
  }
  cv.notify_all();
}

void RolloutStepper::Lookahead::Progress::abandon() {
  {
    std::lock_guard<std::mutex> lock(m);
    abandoned = true;
  }
  cv.notify_all();
}

bool RolloutStepper::Lookahead::Progress::done() {
  std::lock_guard<std::mutex> lock(m);
  return sampled >= total;
}

RolloutStepper::Lookahead::Lookahead(const Lookahead& o) : job(o.job), first(o.first) {
  if (job.valid()) job.get();  // the job's error, if any, is the copy's too
  cache = o.cache;  // the same tensors, as the stepper's own cache_: fork() and rows() give the copy its own
  job = {};
  if (o.job.valid()) {  // a finished job that the copy takes as its own
    std::promise<void> done;
    done.set_value();
    job = done.get_future().share();
  }
}

RolloutStepper::Lookahead& RolloutStepper::Lookahead::operator=(const Lookahead& o) {
  if (this != &o) *this = Lookahead(o);
  return *this;
}

RolloutStepper RolloutStepper::fork() const {
  RolloutStepper c(*this);  // waits for a lookahead job
  c.tokens_ = tokens_.clone();
  for (KVCache* cache : {&c.cache_, &c.ahead_.cache})
    for (auto* layers : {&cache->k, &cache->v})
      for (auto& t : *layers) t = t.clone();
  c.gen_ = gen_.clone();
  return c;
}

RolloutStepper RolloutStepper::rows(const std::vector<int64_t>& futures) const {
  RolloutStepper c(*this);  // waits for a lookahead job; the selections below are its own tensors, copied once
  const int64_t N = int64_t(futures.size());
  std::vector<int64_t> idx(futures);
  if (guided_)  // [cond x N | uncond x N]
    for (int64_t f : futures) idx.push_back(N_ + f);
  const auto index = torch::tensor(idx, torch::kLong).to(dev_);
  auto take = [&](KVCache& cache) {
    for (auto* layers : {&cache.k, &cache.v})
      for (auto& t : *layers) t = t.index_select(0, index);
  };
  c.N_ = N;
  c.tokens_ = tokens_.index_select(0, index);
  take(c.cache_);
  if (!c.ahead_.cache.k.empty()) take(c.ahead_.cache);
  const int64_t B = int64_t(idx.size());
  c.fast_ = o_.fused_tokens && TokenStep::applies(*model_, B) ? (fast_ ? fast_ : std::make_shared<const TokenStep>(*model_))
                                                              : nullptr;
  c.gen_ = gen_.clone();
  return c;
}

RolloutStepper RolloutStepper::repeat(int64_t futures) const {
  if (N_ != 1) fail("only a one-future rollout branches (this one has {} futures)", N_);
  if (futures < 1) fail("branches need at least one future (got {})", futures);
  return rows(std::vector<int64_t>(size_t(futures), 0));
}

RolloutStepper RolloutStepper::select(int64_t i) const {
  if (i < 0 || i >= N_) fail("future {} is not among this rollout's {}", i, N_);
  return rows({i});
}

RolloutResult rollout(WorldModel& model, const RolloutPrompt& prompt, const RolloutOptions& o,
                      const std::function<void(int, int)>& on_frame) {
  auto t_start = std::chrono::steady_clock::now();
  const bool has_prompt = prompt.tokens.defined() && prompt.tokens.numel() > 0;
  const int64_t P = has_prompt ? prompt.tokens.size(-2) : 0, F = o.frames, steps = P + F;
  if (F < 0 || o.futures < 1) fail("rollout needs frames >= 0 and futures >= 1 (got {} and {})", F, o.futures);
  RolloutStepper stepper(model, o, o.futures);
  check_prompt(*model, prompt, o.futures, P, steps);
  for (int64_t k = 0; k < steps; ++k) {
    if (k < P) {
      stepper.step(prompt, prompt.tokens.dim() == 3 ? prompt.tokens.select(1, k) : prompt.tokens[k]);
      continue;
    }
    stepper.step(prompt);
    if (on_frame) on_frame(int(k - P + 1), int(F));
  }
  RolloutResult r;
  r.tokens = stepper.tokens().to(torch::kCPU);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return r;
}

}  // namespace gaia::world
