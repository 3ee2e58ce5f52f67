#include "gaia/world/evaluate.h"

#include <cmath>
#include <limits>

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/world/batch.h"
#include "gaia/world/rollout.h"

namespace gaia::world {

double Score::bits() const { return nats / std::log(2.0); }

namespace {

ConditioningMix only(Conditioning c) {
  switch (c) {
    case Conditioning::kUnconditional: return {1, 0, 0};
    case Conditioning::kAction: return {0, 1, 0};
    case Conditioning::kText: return {0, 0, 1};
  }
  return {};
}

// Cross-entropy of each image token under its logits: logits [..., K], tokens [...] -> nats [...] (float).
torch::Tensor token_nll(const torch::Tensor& logits, const torch::Tensor& tokens) {
  return -torch::log_softmax(logits.to(torch::kFloat), -1).gather(-1, tokens.unsqueeze(-1)).squeeze(-1);
}

}  // namespace

WorldBatch batch_at(const TokenDataset& ds, const std::vector<Window>& windows, size_t b0, int64_t batch,
                    const TextSource& text, int64_t m, const ConditioningMix& mix) {
  std::vector<Window> ws(windows.begin() + long(b0), windows.begin() + long(std::min(windows.size(), b0 + size_t(batch))));
  std::mt19937_64 rng(b0);
  return ds.make_batch(ws, text, m, mix, rng);
}

TextSource text_source(const WorldInfo& info, const TokenDataset& ds) {
  if (!info.embeds_text()) return TextSource(ds.has_captions() ? &info.vocab : nullptr);
  const TextEmbInfo& e = ds.text_emb();
  if (!ds.has_text_emb())
    fail("{}: has no text embeddings, and the world model reads text as embeddings of {} (gaia text embed)",
         ds.path().string(), info.text_encoder);
  if (e.encoder != info.text_encoder || e.m != info.config.world.text_tokens || e.dim != info.config.world.text_dim)
    fail("{}: text embeddings of {} [m = {}, dim = {}], but the world model reads {} [m = {}, dim = {}]",
         ds.path().string(), e.encoder, e.m, e.dim, info.text_encoder, info.config.world.text_tokens,
         info.config.world.text_dim);
  return TextSource::precomputed();
}

Score score(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows, const TextSource& text,
            const ScoreOptions& o) {
  torch::NoGradGuard ng;
  model->eval();
  const auto dev = model->token_embedding->weight.device();
  const int64_t n = model->layout.n;
  Score s;
  s.by_position.assign(static_cast<size_t>(n), 0.0);
  auto sum_pos = torch::zeros({n}, torch::kDouble);
  const auto mix = only(o.mode);
  const size_t W = windows.size();
  for (size_t b0 = 0; b0 < W; b0 += static_cast<size_t>(o.batch)) {
    WorldBatch batch = batch_at(ds, windows, b0, o.batch, text, model->layout.m, mix);
    if (o.shuffle && W > 1) {
      // Conditioning from the window half the set away: a fixed derangement that pairs unrelated episodes.
      std::vector<Window> other;
      for (size_t i = b0; i < b0 + size_t(batch.batch()); ++i) other.push_back(windows[(i + W / 2) % W]);
      std::mt19937_64 rng2(b0);
      WorldBatch c = ds.make_batch(other, text, model->layout.m, mix, rng2);
      batch.actions = c.actions;
      batch.text_ids = c.text_ids;
      batch.text_emb = c.text_emb;
    }
    auto logits = model->forward(batch.to(dev));                             // [B, T, n, K]
    auto tok = batch.tokens.to(dev);
    auto keep = scored_steps(windows, b0, batch.batch(), batch.steps()).to(dev);  // [B, T, 1]
    auto nll = token_nll(logits, tok) * keep;  // [B, T, n], context steps 0
    sum_pos += nll.sum(std::vector<int64_t>{0, 1}).to(torch::kCPU, torch::kDouble);
    s.tokens += keep.sum().item<int64_t>() * n;
  }
  if (s.tokens == 0) return s;
  const double per_pos = double(s.tokens) / double(n);
  for (int64_t i = 0; i < n; ++i) s.by_position[size_t(i)] = sum_pos[i].item<double>() / per_pos;
  s.nats = sum_pos.sum().item<double>() / double(s.tokens);
  return s;
}

Score score_tokens(WorldModel& model, const WorldInfo& info, const torch::Tensor& tokens,
                   const torch::Tensor& actions, int64_t batch) {
  const auto& L = model->layout;
  if (tokens.dim() != 2 || tokens.size(1) != L.n || tokens.size(0) < 1)
    fail("tokens: shape [S >= 1, n = {}] expected, got {}", L.n, shape_str(tokens.sizes().vec()));
  auto z = tokens.to(torch::kCPU).to(torch::kLong).contiguous();
  const auto lo = z.min().item<int64_t>(), hi = z.max().item<int64_t>();
  if (lo < 0 || hi >= info.K) fail("tokens: ids in [0, K = {}) expected, got {}..{}", info.K, lo, hi);
  const int64_t S = z.size(0);
  auto a = torch::full({S, 2}, std::numeric_limits<float>::quiet_NaN());
  if (actions.defined()) {
    if (actions.dim() != 2 || actions.size(0) != S || actions.size(1) != 2)
      fail("actions: shape [{}, 2] expected (one speed and curvature a step), got {}", S,
           shape_str(actions.sizes().vec()));
    a = actions.to(torch::kCPU).to(torch::kFloat).clone();
    if (a.isinf().any().item<bool>()) fail("actions: hold an infinite value");
    a.select(1, 0).div_(kSpeedScale);
    a.select(1, 1).div_(kCurvatureScale);
  }
  torch::NoGradGuard ng;
  model->eval();
  const auto dev = model->token_embedding->weight.device();
  Score s;
  auto sum_pos = torch::zeros({L.n}, torch::kDouble);
  auto run = [&](const torch::Tensor& zb, const torch::Tensor& ab) {  // [B, T', n], [B, T', 2]
    WorldBatch b;
    b.tokens = zb;
    b.actions = ab;
    b.use_action = torch::ones({zb.size(0)}, torch::kBool);
    b.use_text = torch::zeros({zb.size(0)}, torch::kBool);
    auto nll = token_nll(model->forward(b.to(dev)), zb.to(dev));
    sum_pos += nll.sum(std::vector<int64_t>{0, 1}).to(torch::kCPU, torch::kDouble);
    s.tokens += nll.numel();
  };
  const int64_t full = S / L.T;
  for (int64_t w0 = 0; w0 < full; w0 += batch) {
    const int64_t B = std::min(batch, full - w0);
    run(z.narrow(0, w0 * L.T, B * L.T).view({B, L.T, L.n}), a.narrow(0, w0 * L.T, B * L.T).view({B, L.T, 2}));
  }
  if (S % L.T) run(z.narrow(0, full * L.T, S % L.T).unsqueeze(0), a.narrow(0, full * L.T, S % L.T).unsqueeze(0));
  s.by_position.resize(size_t(L.n));
  const double per_pos = double(s.tokens) / double(L.n);
  for (int64_t i = 0; i < L.n; ++i) s.by_position[size_t(i)] = sum_pos[i].item<double>() / per_pos;
  s.nats = sum_pos.sum().item<double>() / double(s.tokens);
  return s;
}

LastFrameScore score_last_frame(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows,
                                const std::optional<SamplingOptions>& sampling, int64_t batch, uint64_t seed) {
  torch::NoGradGuard ng;
  model->eval();
  const auto dev = model->token_embedding->weight.device();
  const int64_t n = model->layout.n;
  LastFrameScore s;
  auto sum_pos = torch::zeros({n}, torch::kDouble);
  int64_t frames = 0, copied = 0;
  for (size_t b0 = 0; b0 < windows.size(); b0 += size_t(batch)) {
    WorldBatch b = batch_at(ds, windows, b0, batch, nullptr, model->layout.m, only(Conditioning::kAction));
    const int64_t B = b.batch(), T = b.steps();
    if (T < 2) fail("score_last_frame: windows need at least 2 steps, got {}", T);
    if (sampling) {  // replace the last frame by the model's own draw
      RolloutPrompt p;
      p.tokens = b.tokens.narrow(1, 0, T - 1);  // [B, T - 1, n] one prompt per future
      p.actions = b.actions;                    // [B, T, 2]
      RolloutOptions ro;
      ro.frames = 1;
      ro.futures = int(B);
      ro.sampling = *sampling;
      ro.seed = seed + b0;
      auto r = rollout(model, p, ro);
      b.tokens = b.tokens.clone();
      b.tokens.select(1, T - 1).copy_(r.tokens.select(1, T - 1).to(b.tokens.device()));
    }
    auto logits = model->forward(b.to(dev)).select(1, T - 1);  // [B, n, K]
    auto tok = b.tokens.select(1, T - 1).to(dev);               // [B, n]
    auto nll = token_nll(logits, tok);
    sum_pos += nll.sum(0).to(torch::kCPU, torch::kDouble);
    copied += (b.tokens.select(1, T - 1) == b.tokens.select(1, T - 2)).sum().item<int64_t>();
    frames += B;
  }
  if (frames == 0) fail("score_last_frame: no window to score");
  s.by_position.resize(size_t(n));
  for (int64_t i = 0; i < n; ++i) s.by_position[size_t(i)] = sum_pos[i].item<double>() / double(frames);
  s.nats = sum_pos.sum().item<double>() / double(frames * n);
  s.copy_rate = double(copied) / double(frames * n);
  return s;
}

SteeringSensitivity steering_sensitivity(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows,
                                         int64_t batch, double threshold) {
  torch::NoGradGuard ng;
  model->eval();
  const auto dev = model->token_embedding->weight.device();
  std::vector<torch::Tensor> base, zeroed, mirrored, curv;
  for (size_t b0 = 0; b0 < windows.size(); b0 += size_t(batch)) {
    WorldBatch b = batch_at(ds, windows, b0, batch, nullptr, model->layout.m, only(Conditioning::kAction));
    auto tok = b.tokens.to(dev);
    auto frame_nll = [&](const torch::Tensor& actions) {  // -> [B, T] mean over the frame's tokens
      WorldBatch x = b;
      x.actions = actions;
      auto logits = model->forward(x.to(dev));
      return token_nll(logits, tok).mean(-1).to(torch::kCPU, torch::kDouble);
    };
    auto c = b.actions.select(2, 1);
    auto a0 = b.actions.clone(), am = b.actions.clone();
    a0.select(2, 1).copy_(torch::where(torch::isnan(c), c, torch::zeros_like(c)));  // NaN stays missing
    am.select(2, 1).copy_(-c);
    base.push_back(frame_nll(b.actions));
    zeroed.push_back(frame_nll(a0));
    mirrored.push_back(frame_nll(am));
    curv.push_back(c.to(torch::kDouble) * kCurvatureScale);
  }
  SteeringSensitivity s;
  if (base.empty()) return s;
  // Frame t >= 1 follows the action of step t - 1.
  auto after = [](const std::vector<torch::Tensor>& v) { return torch::cat(v).slice(1, 1); };
  auto n = after(base), z = after(zeroed), m = after(mirrored);
  auto c = torch::cat(curv).slice(1, 0, -1);
  auto row = [&](const torch::Tensor& sel) {
    SteeringSensitivity::Row r;
    r.frames = sel.sum().item<int64_t>();
    if (r.frames == 0) return r;
    r.nats = n.masked_select(sel).mean().item<double>();
    r.zeroed_rise = (z - n).masked_select(sel).mean().item<double>();
    r.mirrored_rise = (m - n).masked_select(sel).mean().item<double>();
    return r;
  };
  s.left = row(c > threshold);
  s.right = row(c < -threshold);
  s.straight = row(c.abs() <= threshold);  // NaN compares false: left out
  return s;
}

torch::Tensor scored_steps(const std::vector<Window>& windows, size_t w0, int64_t B, int64_t T, int64_t from) {
  auto keep = torch::zeros({B, T - from, 1}, torch::kBool);
  auto k = keep.accessor<bool, 3>();
  for (int64_t b = 0; b < B; ++b)
    for (int64_t t = from; t < T; ++t) k[b][t - from][0] = t >= windows.at(w0 + size_t(b)).scored_from;
  return keep;
}

std::vector<Window> stream_windows(const TokenDataset& ds, const std::vector<size_t>& episodes, int64_t T,
                                   size_t max_windows) {
  const int64_t h = std::max<int64_t>(1, T / 2);
  std::vector<std::vector<Window>> runs;  // each episode's windows in order
  size_t total = 0;
  for (size_t e : episodes) {
    std::vector<Window> run;
    for (int64_t s = 0; s + T <= ds.steps(e); s += h) run.push_back(Window{e, s, T, s == 0 ? 0 : T - h});
    total += run.size();
    if (!run.empty()) runs.push_back(std::move(run));
  }
  std::vector<Window> out;
  if (max_windows == 0 || runs.empty()) return out;
  if (total <= max_windows) {
    for (auto& r : runs) out.insert(out.end(), r.begin(), r.end());
    return out;
  }
  // Whole episodes, evenly spaced, each a contiguous run of windows from its middle (its first one scored whole).
  const size_t E = std::min(runs.size(), max_windows), per = max_windows / E;
  for (size_t i = 0; i < E; ++i) {
    const auto& r = runs[i * runs.size() / E];
    const size_t q = std::min(per, r.size()), j0 = (r.size() - q) / 2;
    for (size_t j = j0; j < j0 + q; ++j) {
      Window w = r[j];
      if (j == j0) w.scored_from = 0;
      out.push_back(w);
    }
  }
  return out;
}

std::vector<Window> validation_windows(const TokenDataset& ds, const std::vector<size_t>& episodes, int64_t T,
                                       size_t max_windows) {
  auto all = ds.windows(episodes, T, T);  // non-overlapping
  if (all.size() <= max_windows) return all;
  std::vector<Window> out;
  for (size_t i = 0; i < max_windows; ++i) out.push_back(all[i * all.size() / max_windows]);
  return out;
}

}  // namespace gaia::world
