#include "gaia/world/model.h"

#include "gaia/core/error.h"

namespace gaia::world {

namespace F = torch::nn::functional;

WorldModelImpl::WorldModelImpl(const WorldConfig& c, int64_t n, int64_t K_) : cfg(c), K(K_), d(c.d_model) {
  if (c.action_tokens != 2) fail("world.action_tokens must be 2 (speed and curvature, paper §2.1), got {}", c.action_tokens);
  if (n <= 0 || K <= 0) fail("world model needs n > 0 image tokens and K > 0 codes (got n = {}, K = {})", n, K);
  if (c.d_model % c.n_heads != 0) fail("world.d_model {} is not divisible by world.n_heads {}", c.d_model, c.n_heads);
  layout = SequenceLayout{c.text_tokens, n, c.action_tokens, c.context_steps};
  token_embedding = register_module("token_embedding", torch::nn::Embedding(K, d));
  word_embedding = register_module("word_embedding", torch::nn::Embedding(c.text_vocab, c.text_dim));
  text_proj = register_module("text_proj", torch::nn::Linear(c.text_dim, d));
  speed_proj = register_module("speed_proj", torch::nn::Linear(1, d));
  curvature_proj = register_module("curvature_proj", torch::nn::Linear(1, d));
  if (c.action_mlp > 0) {
    auto mlp = [&](const char* name) {
      return register_module(name, torch::nn::Sequential(torch::nn::Linear(1, c.action_mlp), torch::nn::GELU(),
                                                         torch::nn::Linear(c.action_mlp, d)));
    };
    speed_mlp = mlp("speed_mlp");
    curvature_mlp = mlp("curvature_mlp");
  }
  // GPT-2 style small-normal initialisation of the learned tokens and positions.
  null_text = register_parameter("null_text", torch::randn({layout.m, d}) * 0.02);
  null_action = register_parameter("null_action", torch::randn({layout.l, d}) * 0.02);
  temporal_pos = register_parameter("temporal_pos", torch::randn({layout.T, d}) * 0.02);
  spatial_pos = register_parameter("spatial_pos", torch::randn({layout.per_step(), d}) * 0.02);
  blocks = register_module("blocks", torch::nn::ModuleList());
  for (int i = 0; i < c.n_layers; ++i) blocks->push_back(Block(d, c.n_heads));
  ln_f = register_module("ln_f", torch::nn::LayerNorm(torch::nn::LayerNormOptions({d})));
  head = register_module("head", torch::nn::Linear(torch::nn::LinearOptions(d, K).bias(false)));
  for (auto& p : named_parameters()) {
    const auto& k = p.key();
    torch::NoGradGuard ng;
    if (k.find("weight") != std::string::npos && p.value().dim() == 2) p.value().normal_(0.0, 0.02);
    if (k.find("bias") != std::string::npos) p.value().zero_();
    // GPT-2: residual projections scaled by 1/sqrt(2 * layers) so the residual stream does not grow with depth.
    if (k.find("proj.weight") != std::string::npos && k.find("blocks") != std::string::npos)
      p.value().normal_(0.0, 0.02 / std::sqrt(2.0 * c.n_layers));
  }
  // The action MLPs' kinks spread over the inputs' range (about [-2, 2] normalised, batch.h), and their output
  // starts at zero: a new MLP leaves the linear layers' embedding as it was (fine-tuning from a model without one).
  for (auto* mlp : {&speed_mlp, &curvature_mlp}) {
    if (!*mlp) continue;
    torch::NoGradGuard ng;
    auto first = (*mlp)[0]->as<torch::nn::Linear>(), last = (*mlp)[2]->as<torch::nn::Linear>();
    first->weight.normal_(0.0, 1.0);
    first->bias.uniform_(-2.0, 2.0);
    last->weight.zero_();
    last->bias.zero_();
  }
}

namespace {

// Per-example switch: mask [B] bool -> where(mask, a, b) broadcast over the trailing dims of a.
torch::Tensor choose(const torch::Tensor& mask, const torch::Tensor& a, const torch::Tensor& b) {
  if (!mask.defined()) return a;
  auto m = mask.to(a.device()).to(torch::kBool);
  for (int64_t i = 1; i < a.dim(); ++i) m = m.unsqueeze(-1);
  return torch::where(m, a, b);
}

}  // namespace

torch::Tensor WorldModelImpl::embed_text(const WorldBatch& b, int64_t t0) {
  const int64_t B = b.batch(), T = b.steps(), m = layout.m;
  auto null = null_text.view({1, 1, m, d}).expand({B, T, m, d});
  torch::Tensor feats;
  if (b.text_emb.defined()) {
    if (b.text_emb.size(2) != m || b.text_emb.size(3) != cfg.text_dim)
      fail("text embeddings have shape [{}, {}, {}, {}] but the world model takes [B, T, m = {}, text_dim = {}]",
           b.text_emb.size(0), b.text_emb.size(1), b.text_emb.size(2), b.text_emb.size(3), m, cfg.text_dim);
    feats = b.text_emb;
  } else if (b.text_ids.defined()) {
    feats = word_embedding->forward(b.text_ids.clamp(0, cfg.text_vocab - 1));
  }
  auto x = feats.defined() ? choose(b.use_text, text_proj->forward(feats), null) : null;
  return x + temporal_pos.narrow(0, t0, T).view({1, T, 1, d}) + spatial_pos.narrow(0, 0, m).view({1, 1, m, d});
}

torch::Tensor WorldModelImpl::embed_image(const torch::Tensor& tokens, int64_t t0, int64_t slot0) {
  const int64_t B = tokens.size(0), T = tokens.size(1), k = tokens.size(2);
  return token_embedding->forward(tokens) + temporal_pos.narrow(0, t0, T).view({1, T, 1, d}) +
         spatial_pos.narrow(0, layout.image_slot(slot0), k).view({1, 1, k, d}).expand({B, T, k, d});
}

torch::Tensor WorldModelImpl::embed_actions(const WorldBatch& b, int64_t t0) {
  const int64_t B = b.batch(), T = b.steps(), l = layout.l;
  auto null = null_action.view({1, 1, l, d}).expand({B, T, l, d});
  torch::Tensor x = null;
  if (b.actions.defined()) {
    auto a = b.actions.to(torch::kFloat);
    auto missing = torch::isnan(a);                          // [B, T, 2]
    auto a0 = torch::where(missing, torch::zeros_like(a), a);  // keep NaN out of the graph
    auto speed = a0.narrow(2, 0, 1), curvature = a0.narrow(2, 1, 1);  // [B, T, 1] each
    auto es = speed_proj->forward(speed), ec = curvature_proj->forward(curvature);  // [B, T, d] each
    if (speed_mlp) {
      es = es + speed_mlp->forward(speed);
      ec = ec + curvature_mlp->forward(curvature);
    }
    auto e = torch::stack({es, ec}, 2);                      // [B, T, 2, d]
    x = torch::where(missing.unsqueeze(-1), null, e);
    x = choose(b.use_action, x, null);
  }
  return x + temporal_pos.narrow(0, t0, T).view({1, T, 1, d}) +
         spatial_pos.narrow(0, layout.action_slot(0), l).view({1, 1, l, d});
}

torch::Tensor WorldModelImpl::embed(const WorldBatch& b, int64_t t0) {
  const int64_t B = b.batch(), T = b.steps();
  if (t0 + T > layout.T) fail("{} steps from temporal position {} exceed the context of {} steps", T, t0, layout.T);
  if (b.tokens.size(2) != layout.n)
    fail("image tokens have {} per frame but the world model was built for n = {}", b.tokens.size(2), layout.n);
  auto x = torch::cat({embed_text(b, t0), embed_image(b.tokens, t0), embed_actions(b, t0)}, 2);  // [B, T, S, d]
  return x.reshape({B, T * layout.per_step(), d});
}

torch::Tensor WorldModelImpl::body(const torch::Tensor& x, KVCache* cache) {
  auto h = x;
  int i = 0;
  for (auto& m : *blocks) {
    Block blk(std::dynamic_pointer_cast<BlockImpl>(m));
    // Checkpointing only pays (and only applies) when training: no cache, gradients on.
    h = cfg.activation_checkpointing && !cache && is_training() ? checkpointed(blk, h) : blk->forward(h, cache, i);
    ++i;
  }
  if (cache) cache->length += x.size(1);
  return ln_f->forward(h);
}

void WorldModelImpl::prefill(const torch::Tensor& x, KVCache& cache) {
  auto h = x;
  const int last = int(blocks->size()) - 1;
  for (int i = 0; i < last; ++i) h = (*blocks)[static_cast<size_t>(i)]->as<BlockImpl>()->forward(h, &cache, i);
  (*blocks)[static_cast<size_t>(last)]->as<BlockImpl>()->append_kv(h, cache, last);
  cache.length += x.size(1);
}

torch::Tensor WorldModelImpl::forward(const WorldBatch& b) {
  const int64_t B = b.batch(), T = b.steps(), n = layout.n;
  auto h = body(embed(b));  // [B, T * S, d]
  // Only the n outputs per step that predict image tokens go through the head (eq. 1 has no other terms).
  std::vector<int64_t> idx;
  idx.reserve(static_cast<size_t>(T * n));
  for (int64_t t = 0; t < T; ++t)
    for (int64_t i = 0; i < n; ++i) idx.push_back(layout.predictor(t, i));
  auto sel = torch::tensor(idx, torch::TensorOptions().dtype(torch::kLong)).to(h.device());
  return CopyBias::of(cfg).apply(logits(h.index_select(1, sel)).view({B, T, n, K}), b.tokens);
}

torch::Tensor with_copy_bias(const torch::Tensor& logits, const torch::Tensor& prev, const torch::Tensor& bias) {
  return logits.scatter_add(-1, prev.to(torch::kLong).unsqueeze(-1), bias.to(logits.dtype()).unsqueeze(-1));
}

torch::Tensor CopyBias::per_slot(const torch::Tensor& cur, const torch::Tensor& prev) const {
  auto kept = (cur == prev).to(torch::kDouble);                                    // [..., n]
  auto before = torch::constant_pad_nd(kept.narrow(-1, 0, kept.size(-1) - 1), {1, 0});  // slot i: slot i - 1 kept
  return before * run + bias;  // bias + run exactly where a run goes on, as at()
}

torch::Tensor CopyBias::apply(const torch::Tensor& logits, const torch::Tensor& tokens) const {
  const int64_t T = logits.size(1);
  if (!any() || T < 2) return logits;
  // Frame 0 of a window has no earlier frame in view.
  auto tok = tokens.to(logits.device(), torch::kLong);
  auto prev = tok.slice(1, 0, T - 1), cur = tok.slice(1, 1);
  return torch::cat({logits.narrow(1, 0, 1), with_copy_bias(logits.slice(1, 1), prev, per_slot(cur, prev))}, 1);
}

KVCache WorldModelImpl::make_cache(int64_t batch, int64_t capacity, c10::optional<torch::ScalarType> dtype) const {
  KVCache c;
  const int64_t H = cfg.n_heads, hd = d / H;
  auto opts = token_embedding->weight.options().requires_grad(false);
  if (dtype) opts = opts.dtype(*dtype);
  for (int i = 0; i < cfg.n_layers; ++i) {
    c.k.push_back(torch::empty({batch, H, hd, capacity}, opts));  // keys transposed (transformer.h)
    c.v.push_back(torch::empty({batch, H, capacity, hd}, opts));
  }
  return c;
}

int64_t WorldModelImpl::parameter_count(bool with_word_embedding) const {
  int64_t total = 0;
  for (const auto& p : named_parameters())
    if (with_word_embedding || p.key().rfind("word_embedding.", 0) != 0) total += p.value().numel();
  return total;
}

torch::Tensor image_token_loss(const torch::Tensor& logits, const torch::Tensor& tokens) {
  // In float32 whatever the compute precision: log-softmax over K in bf16 loses the small probabilities.
  return F::cross_entropy(logits.reshape({-1, logits.size(-1)}).to(torch::kFloat), tokens.reshape({-1}).to(torch::kLong));
}

}  // namespace gaia::world
