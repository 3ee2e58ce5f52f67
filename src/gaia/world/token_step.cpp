#include "gaia/world/token_step.h"

#include <ATen/autocast_mode.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "gaia/core/error.h"
#include "gaia/torch/simd.h"
#include "gaia/world/transformer.h"

namespace gaia::world {

namespace {

constexpr int64_t kMaxRows = TokenStep::kMaxRows;

torch::Tensor copied(const torch::Tensor& t) { return t.detach().contiguous().clone(); }

constexpr int64_t kLanes = kSimdLanes;

// A linear layer's weight [out, in] packed for linear_rows: [out / 64][in][64] (then the last out % 64 outputs as
// [in][out % 64]), so that each run of 64 outputs reads one contiguous stretch of memory.
torch::Tensor packed(const torch::Tensor& w) {
  const int64_t out = w.size(0), in = w.size(1), full = out / kLanes * kLanes;
  auto wt = w.detach().to(torch::kFloat).t().contiguous();  // [in, out]
  std::vector<torch::Tensor> parts;
  if (full > 0) parts.push_back(wt.narrow(1, 0, full).view({in, full / kLanes, kLanes}).permute({1, 0, 2}).reshape(-1));
  if (full < out) parts.push_back(wt.narrow(1, full, out - full).contiguous().reshape(-1));
  return torch::cat(parts).contiguous();
}

// Outputs [sub, sub + 8 V) of one packed block ([in][64], its bias and outputs at `bias` and `y`) for B rows, all
// rows at once: each weight is read once for every row, and the B x V accumulators of 8 floats stay in registers.
// One broadcast multiply and add per input over a contiguous slice (no horizontal sums): every output sums its
// inputs in order, whatever B, so the rows of a batch get the numbers they would get alone.
using Floats8 = float __attribute__((vector_size(32)));
template <int B, int V>
[[gnu::always_inline]] inline void block_rows(const float* x, int64_t in, const float* blk, int64_t sub,
                                              const float* bias, float* y, int64_t out) {
  Floats8 acc[B][V];
  for (int b = 0; b < B; ++b)
    for (int v = 0; v < V; ++v) {
      if (bias) std::memcpy(&acc[b][v], bias + sub + 8 * v, sizeof(Floats8));
      else acc[b][v] = Floats8{};
    }
  for (int64_t i = 0; i < in; ++i) {
    const float* row = blk + i * kLanes + sub;
    Floats8 xi[B];
    for (int b = 0; b < B; ++b) xi[b] = Floats8{} + x[b * in + i];
    for (int v = 0; v < V; ++v) {
      Floats8 w;
      std::memcpy(&w, row + 8 * v, sizeof(Floats8));
      for (int b = 0; b < B; ++b) acc[b][v] += xi[b] * w;
    }
  }
  for (int b = 0; b < B; ++b)
    for (int v = 0; v < V; ++v) std::memcpy(y + b * out + sub + 8 * v, &acc[b][v], sizeof(Floats8));
}

// y[b] = bias + x[b] W for B <= kMaxRows rows with W packed as above. A single token's products are bound by
// reading the weights, not by arithmetic, so rows share every read.
GAIA_SIMD_CLONES void linear_rows(const float* x, int64_t B, const float* wp, const float* bias, int64_t in,
                                  int64_t out, float* y) {
  static_assert(kLanes == 64 && kMaxRows == 4, "block_rows splits a block of 64 outputs among up to 4 rows");
  const int64_t full = out / kLanes * kLanes, rest = out - full;
  for (int64_t o0 = 0; o0 < full; o0 += kLanes) {
    const float* blk = wp + o0 * in;  // [in][64]
    const float* bb = bias ? bias + o0 : nullptr;
    float* yo = y + o0;
    switch (B) {
      case 1: block_rows<1, 8>(x, in, blk, 0, bb, yo, out); break;
      case 2: for (int64_t sub = 0; sub < kLanes; sub += 32) block_rows<2, 4>(x, in, blk, sub, bb, yo, out); break;
      case 3: for (int64_t sub = 0; sub < kLanes; sub += 16) block_rows<3, 2>(x, in, blk, sub, bb, yo, out); break;
      default: for (int64_t sub = 0; sub < kLanes; sub += 16) block_rows<4, 2>(x, in, blk, sub, bb, yo, out); break;
    }
  }
  const float* tail = wp + full * in;  // [in][rest]
  for (int64_t b = 0; b < B; ++b)
    for (int64_t o = 0; o < rest; ++o) {
      float a = bias ? bias[full + o] : 0.0f;
      for (int64_t i = 0; i < in; ++i) a += x[b * in + i] * tail[i * rest + o];
      y[b * out + full + o] = a;
    }
}

// LayerNorm over the last dimension d of B rows (biased variance, as torch::nn::LayerNorm).
void layer_norm_rows(const float* x, int64_t B, int64_t d, const float* w, const float* bias, double eps, float* y) {
  for (int64_t b = 0; b < B; ++b) {
    const float* xb = x + b * d;
    double mean = 0, var = 0;
    for (int64_t i = 0; i < d; ++i) mean += xb[i];
    mean /= double(d);
    for (int64_t i = 0; i < d; ++i) var += (xb[i] - mean) * (xb[i] - mean);
    const float inv = float(1.0 / std::sqrt(var / double(d) + eps)), m = float(mean);
    for (int64_t i = 0; i < d; ++i) y[b * d + i] = (xb[i] - m) * inv * w[i] + bias[i];
  }
}

void gelu_inplace(float* x, int64_t n) {  // exact GELU, as F::gelu's default
  for (int64_t i = 0; i < n; ++i) x[i] = 0.5f * x[i] * (1.0f + std::erf(x[i] * float(M_SQRT1_2)));
}

const float* f32(const torch::Tensor& t) { return t.data_ptr<float>(); }

}  // namespace

bool TokenStep::applies(const WorldModelImpl& m, int64_t rows) {
  const auto& w = m.token_embedding->weight;
  return rows <= kMaxRows && w.device().is_cpu() && w.scalar_type() == torch::kFloat &&
         (!at::autocast::is_cpu_enabled() || at::autocast::get_autocast_cpu_dtype() == at::kBFloat16);
}

TokenStep::TokenStep(const WorldModelImpl& m)
    : d_(m.d), K_(m.K), heads_(m.cfg.n_heads), image_slot0_(m.layout.image_slot(0)) {
  embedding_ = copied(m.token_embedding->weight);
  temporal_ = copied(m.temporal_pos);
  spatial_ = copied(m.spatial_pos);
  for (const auto& mod : *m.blocks) {
    auto blk = std::dynamic_pointer_cast<BlockImpl>(mod);
    Layer l;
    l.ln1_w = copied(blk->ln1->weight), l.ln1_b = copied(blk->ln1->bias), l.eps1 = blk->ln1->options.eps();
    l.qkv_p = packed(blk->attn->qkv->weight), l.qkv_b = copied(blk->attn->qkv->bias);
    l.proj_p = packed(blk->attn->proj->weight), l.proj_b = copied(blk->attn->proj->bias);
    l.ln2_w = copied(blk->ln2->weight), l.ln2_b = copied(blk->ln2->bias), l.eps2 = blk->ln2->options.eps();
    l.fc_p = packed(blk->fc->weight), l.fc_b = copied(blk->fc->bias);
    l.fc_proj_p = packed(blk->fc_proj->weight), l.fc_proj_b = copied(blk->fc_proj->bias);
    layers_.push_back(std::move(l));
  }
  lnf_w_ = copied(m.ln_f->weight), lnf_b_ = copied(m.ln_f->bias), eps_f_ = m.ln_f->options.eps();
  head_p_ = packed(m.head->weight);
}

torch::Tensor TokenStep::logits(const torch::Tensor& tokens, int64_t t, int64_t slot, KVCache& cache) const {
  torch::NoGradGuard ng;
  const int64_t B = tokens.numel(), d = d_;
  if (cache.k.size() != layers_.size() || cache.k[0].size(0) != B || cache.length >= cache.capacity() ||
      !fused_cache(cache.k[0], cache.v[0]))
    fail("token step: the cache must hold {} layers of {} float32 or bf16 rows with room for one more position",
         layers_.size(), B);
  auto ids = tokens.to(torch::kCPU).to(torch::kLong).contiguous();
  const int64_t* id = ids.data_ptr<int64_t>();
  const int64_t H = heads_, cap = cache.capacity();
  // The step's activations in buffers of its thread, reused token after token (no allocation a token).
  thread_local std::vector<float> scratch;
  scratch.resize(size_t(B * (d + d + 3 * d + 4 * d + d + d + H * cap)));
  float *xp = scratch.data(), *hp = xp + B * d, *qkv = hp + B * d, *up = qkv + B * 3 * d, *yp = up + B * 4 * d,
        *att = yp + B * d, *scores = att + B * d;
  const float *emb = f32(embedding_), *tp = f32(temporal_) + t * d, *sp = f32(spatial_) + (image_slot0_ + slot) * d;
  for (int64_t b = 0; b < B; ++b) {
    if (id[b] < 0 || id[b] >= K_) fail("token step: token {} outside [0, K = {})", id[b], K_);
    const float* e = emb + id[b] * d;
    for (int64_t i = 0; i < d; ++i) xp[b * d + i] = e[i] + tp[i] + sp[i];  // as embed_image: token + t + slot
  }
  for (size_t li = 0; li < layers_.size(); ++li) {
    const Layer& l = layers_[li];
    layer_norm_rows(xp, B, d, f32(l.ln1_w), f32(l.ln1_b), l.eps1, hp);
    linear_rows(hp, B, f32(l.qkv_p), f32(l.qkv_b), d, 3 * d, qkv);
    attend_one_cached(qkv, B, d, H, cache.k[li], cache.v[li], cache.length, scores, att);  // [B, d]
    linear_rows(att, B, f32(l.proj_p), f32(l.proj_b), d, d, yp);
    for (int64_t i = 0; i < B * d; ++i) xp[i] += yp[i];
    layer_norm_rows(xp, B, d, f32(l.ln2_w), f32(l.ln2_b), l.eps2, hp);
    linear_rows(hp, B, f32(l.fc_p), f32(l.fc_b), d, 4 * d, up);
    gelu_inplace(up, B * 4 * d);
    linear_rows(up, B, f32(l.fc_proj_p), f32(l.fc_proj_b), 4 * d, d, yp);
    for (int64_t i = 0; i < B * d; ++i) xp[i] += yp[i];
  }
  cache.length += 1;
  layer_norm_rows(xp, B, d, f32(lnf_w_), f32(lnf_b_), eps_f_, hp);
  auto out = torch::empty({B, K_}, torch::TensorOptions().dtype(torch::kFloat));
  linear_rows(hp, B, f32(head_p_), nullptr, d, K_, out.data_ptr<float>());
  return out;
}

}  // namespace gaia::world
