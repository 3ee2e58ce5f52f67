#include "gaia/world/transformer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include <ATen/Parallel.h>

#include <torch/version.h>

#include "gaia/core/error.h"
#include "gaia/torch/attention.h"
#include "gaia/torch/exp8.h"
#include "gaia/torch/simd.h"

namespace gaia::world {

namespace F = torch::nn::functional;

CausalSelfAttentionImpl::CausalSelfAttentionImpl(int64_t d_, int64_t heads_) : heads(heads_), d(d_) {
  TORCH_CHECK(d % heads == 0, "d_model ", d, " is not divisible by n_heads ", heads);
  qkv = register_module("qkv", torch::nn::Linear(d, 3 * d));
  proj = register_module("proj", torch::nn::Linear(d, d));
}

namespace {

// Queries per block when many are appended to a cache on the CPU (filling it, as the sliding window does).
constexpr int64_t kQueryBlock = 128;

// q [B, H, Lq, hd], kT [B, H, hd, Lk] (keys transposed), v [B, H, Lk, hd]; query i sits at key position
// offset + i and sees keys <= that. `cached`: the keys are a cache being filled (inference), where long appends on
// the CPU attend block by block; training keeps the one square its memory plan counts.
torch::Tensor attend(const torch::Tensor& q, const torch::Tensor& kT, const torch::Tensor& v, int64_t offset,
                     bool cached) {
  const int64_t Lq = q.size(2), Lk = kT.size(3);
  const auto k = kT.transpose(2, 3);
  if (Lq == 1) return attention(q, k, v);  // one query after the cached keys sees all of them
  if (cached && q.device().is_cpu() && Lq > 2 * kQueryBlock) {
    // Block by block, each seeing only the keys up to its last query: the scores above the diagonal, about half
    // of a square's, are mostly never computed.
    std::vector<torch::Tensor> parts;
    for (int64_t a = 0; a < Lq; a += kQueryBlock) {
      const int64_t n = std::min(kQueryBlock, Lq - a), keys = offset + a + n;
      parts.push_back(attention(q.narrow(2, a, n), k.narrow(2, 0, keys), v.narrow(2, 0, keys),
                                causal_mask(n, keys, offset + a, q.options())));
    }
    return torch::cat(parts, 2);
  }
  if (offset == 0 && Lq == Lk) return attention(q, k, v, {}, /*causal=*/true);
  return attention(q, k, v, causal_mask(Lq, Lk, offset, q.options()));
}

// The two inner loops of one query's attention (torch/simd.h: also compiled for AVX2), over a float32 cache or a
// bf16 one (torch's kBFloat16: a float's upper 16 bits, widened by a shift as they are read).
[[gnu::always_inline]] inline float widen(float x) { return x; }
[[gnu::always_inline]] inline float widen(uint16_t x) {
  const uint32_t u = uint32_t(x) << 16;
  float f;
  std::memcpy(&f, &u, sizeof f);
  return f;
}

// out[j] = scale * q . k_j for j < Lk, keys transposed (KT row e holds component e of every key, row stride `cap`):
// four components at a time, each a contiguous row streamed over every key into `out` (a few KB, held in L1), so
// memory is read as four sequential streams, not hd strided ones. Each key still sums its components in order.
template <class T>
[[gnu::always_inline]] inline void score_keys_of(const float* q, const T* KT, int64_t cap, int64_t Lk, int64_t hd,
                                                 float scale, float* __restrict out) {
  std::fill(out, out + Lk, 0.0f);
  int64_t e = 0;
  for (; e + 4 <= hd; e += 4) {
    const float q0 = q[e] * scale, q1 = q[e + 1] * scale, q2 = q[e + 2] * scale, q3 = q[e + 3] * scale;
    const T* __restrict r0 = KT + e * cap;
    const T *__restrict r1 = r0 + cap, *__restrict r2 = r1 + cap, *__restrict r3 = r2 + cap;
    for (int64_t j = 0; j < Lk; ++j)
      out[j] = (((out[j] + q0 * widen(r0[j])) + q1 * widen(r1[j])) + q2 * widen(r2[j])) + q3 * widen(r3[j]);
  }
  for (; e < hd; ++e) {
    const float qe = q[e] * scale;
    const T* __restrict r = KT + e * cap;
    for (int64_t j = 0; j < Lk; ++j) out[j] += qe * widen(r[j]);
  }
}
GAIA_SIMD_CLONES void score_keys(const float* q, const float* KT, int64_t cap, int64_t Lk, int64_t hd, float scale,
                                 float* __restrict out) {
  score_keys_of(q, KT, cap, Lk, hd, scale, out);
}
GAIA_SIMD_CLONES void score_keys(const float* q, const uint16_t* KT, int64_t cap, int64_t Lk, int64_t hd, float scale,
                                 float* __restrict out) {
  score_keys_of(q, KT, cap, Lk, hd, scale, out);
}

// y = sum_j p[j] V[j] over Lk rows of hd floats, 32 components at a time in registers, even and odd rows in two
// sets of sums (one chain of dependent multiply-adds would wait on each one's latency).
template <class T>
[[gnu::always_inline]] inline void weighted_sum_of(const float* p, const T* V, int64_t Lk, int64_t hd, float* y) {
  constexpr int64_t kE = 32;
  int64_t e0 = 0;
  for (; e0 + kE <= hd; e0 += kE) {
    float even[kE] = {}, odd[kE] = {};
    int64_t j = 0;
    for (; j + 2 <= Lk; j += 2) {
      const float w0 = p[j], w1 = p[j + 1];
      const T *v0 = V + j * hd + e0, *v1 = v0 + hd;
      for (int64_t e = 0; e < kE; ++e) {
        even[e] += w0 * widen(v0[e]);
        odd[e] += w1 * widen(v1[e]);
      }
    }
    if (j < Lk)
      for (int64_t e = 0; e < kE; ++e) even[e] += p[j] * widen(V[j * hd + e0 + e]);
    for (int64_t e = 0; e < kE; ++e) y[e0 + e] = even[e] + odd[e];
  }
  for (; e0 < hd; ++e0) {
    float a = 0;
    for (int64_t j = 0; j < Lk; ++j) a += p[j] * widen(V[j * hd + e0]);
    y[e0] = a;
  }
}
GAIA_SIMD_CLONES void weighted_sum(const float* p, const float* V, int64_t Lk, int64_t hd, float* y) {
  weighted_sum_of(p, V, Lk, hd, y);
}
GAIA_SIMD_CLONES void weighted_sum(const float* p, const uint16_t* V, int64_t Lk, int64_t hd, float* y) {
  weighted_sum_of(p, V, Lk, hd, y);
}

[[gnu::always_inline]] inline void store(float* to, float x) { *to = x; }
[[gnu::always_inline]] inline void store(uint16_t* to, float x) { *to = c10::BFloat16(x).x; }  // rounded to nearest even

}  // namespace

GAIA_SIMD_CLONES void softmax_rows(float* s, int64_t rows, int64_t n) {
  for (int64_t row = 0; row < rows; ++row) {
    float* x = s + row * n;
    float top = -std::numeric_limits<float>::infinity();
    for (int64_t j = 0; j < n; ++j) top = std::max(top, x[j]);
    Floats8 sum8{};
    int64_t j = 0;
    for (; j + 8 <= n; j += 8) {
      Floats8 v;
      std::memcpy(&v, x + j, sizeof v);
      v = exp8(v - top);
      std::memcpy(x + j, &v, sizeof v);
      sum8 += v;
    }
    float sum = 0;
    for (int e = 0; e < 8; ++e) sum += sum8[e];
    if (j < n) {  // the last few through the same polynomial
      Floats8 v{};
      for (int64_t e = j; e < n; ++e) v[e - j] = x[e] - top;
      v = exp8(v);
      for (int64_t e = j; e < n; ++e) x[e] = v[e - j], sum += v[e - j];
    }
    const float inv = 1.0f / sum;
    for (int64_t e = 0; e < n; ++e) x[e] *= inv;
  }
}

namespace {

template <class T>
void attend_rows(const float* in, int64_t B, int64_t d, int64_t heads, T* kc, T* vc, int64_t cap, int64_t offset,
                 float* sc, float* y) {
  const int64_t hd = d / heads, Lk = offset + 1;
  const float scale = float(1.0 / std::sqrt(double(hd)));
  // Pass 1: append this token's key and value, score the query against every cached key, normalise.
  at::parallel_for(0, B * heads, 1, [&](int64_t begin, int64_t end) {
    for (int64_t bh = begin; bh < end; ++bh) {
      const int64_t b = bh / heads, h = bh % heads;
      const float* q = in + b * 3 * d + h * hd;
      T* kb = kc + (bh * hd) * cap;  // KT[b, h, 0, 0]
      T* vb = vc + (bh * cap + offset) * hd;
      for (int64_t e = 0; e < hd; ++e) store(kb + e * cap + offset, q[d + e]), store(vb + e, q[2 * d + e]);
      score_keys(q, kb, cap, Lk, hd, scale, sc + bh * Lk);
      softmax_rows(sc + bh * Lk, 1, Lk);
    }
  });
  // Pass 2: y = sum_j p_j v_j, written straight into the head's slice of the output row.
  at::parallel_for(0, B * heads, 1, [&](int64_t begin, int64_t end) {
    for (int64_t bh = begin; bh < end; ++bh) {
      const int64_t b = bh / heads, h = bh % heads;
      weighted_sum(sc + bh * Lk, vc + (bh * cap) * hd, Lk, hd, y + b * d + h * hd);
    }
  });
}

}  // namespace

bool fused_cache(const torch::Tensor& K, const torch::Tensor& V) {
  return K.device().is_cpu() && K.is_contiguous() && V.is_contiguous() && K.scalar_type() == V.scalar_type() &&
         (K.scalar_type() == torch::kFloat || K.scalar_type() == torch::kBFloat16);
}

// Sampling's case: one new token per row appended to a CPU cache. The general path spends ~20 small LibTorch
// operations per layer on views, cache writes and two batched products of a single query; here the cache write and
// the scores are one pass over raw memory, then the softmax and one weighted sum (docs/benchmarks.md).
void attend_one_cached(const float* in, int64_t B, int64_t d, int64_t heads, torch::Tensor& K, torch::Tensor& V,
                       int64_t offset, float* sc, float* y) {
  if (!fused_cache(K, V)) fail("cached attention: the cache must be contiguous float32 or bf16 on the CPU");
  const int64_t cap = K.size(3);
  if (K.scalar_type() == torch::kFloat)
    attend_rows(in, B, d, heads, K.data_ptr<float>(), V.data_ptr<float>(), cap, offset, sc, y);
  else
    attend_rows(in, B, d, heads, reinterpret_cast<uint16_t*>(K.data_ptr<at::BFloat16>()),
                reinterpret_cast<uint16_t*>(V.data_ptr<at::BFloat16>()), cap, offset, sc, y);
}

// qkv [B, 3d] (per row: q | k | v, each H x hd) -> [B, d]; the cache grows by one at `offset`.
torch::Tensor attend_one_cached(const torch::Tensor& qkv, torch::Tensor& K, torch::Tensor& V, int64_t offset,
                                int64_t heads) {
  const int64_t B = qkv.size(0), d = qkv.size(1) / 3;
  auto src = qkv.contiguous();
  auto out = torch::empty({B, d}, qkv.options());
  auto scores = torch::empty({B * heads, offset + 1}, qkv.options());
  attend_one_cached(src.data_ptr<float>(), B, d, heads, K, V, offset, scores.data_ptr<float>(), out.data_ptr<float>());
  return out;
}

torch::Tensor CausalSelfAttentionImpl::forward(const torch::Tensor& x, KVCache* cache, int layer) {
  const int64_t B = x.size(0), L = x.size(1), hd = d / heads;
  if (cache && cache->fused_single_token && L == 1 && x.device().is_cpu() && x.scalar_type() == torch::kFloat && !torch::GradMode::is_enabled()) {
    auto& K = cache->k[static_cast<size_t>(layer)];
    auto& V = cache->v[static_cast<size_t>(layer)];
    TORCH_CHECK(cache->length < cache->capacity(), "KV cache overflow: ", cache->length, " + 1 > ", cache->capacity());
    if (fused_cache(K, V)) {
      auto x2 = x.view({B, d});  // 2-D products: LibTorch's linear pays for folding a 3-D input on every call
      // float32 attention over the cache; the projections take autocast's precision (bf16: their outputs are bf16)
      auto q_k_v = qkv->forward(x2).to(torch::kFloat);
      return proj->forward(attend_one_cached(q_k_v, K, V, cache->length, heads)).view({B, 1, d});
    }
  }
  auto qkv_ = qkv->forward(x).view({B, L, 3, heads, hd}).permute({2, 0, 3, 1, 4});  // [3, B, H, L, hd]
  auto q = qkv_[0], k = qkv_[1], v = qkv_[2];
  auto kT = k.transpose(2, 3);  // [B, H, hd, L]
  int64_t offset = 0;
  if (cache) {
    offset = cache->length;
    TORCH_CHECK(offset + L <= cache->capacity(), "KV cache overflow: ", offset, " + ", L, " > ", cache->capacity());
    auto& K = cache->k[static_cast<size_t>(layer)];
    auto& V = cache->v[static_cast<size_t>(layer)];
    K.narrow(3, offset, L).copy_(k.transpose(2, 3));
    V.narrow(2, offset, L).copy_(v);
    kT = K.narrow(3, 0, offset + L);
    v = V.narrow(2, 0, offset + L);
  }
  auto y = attend(q, kT, v, offset, cache != nullptr);  // [B, H, L, hd]
  return proj->forward(y.transpose(1, 2).reshape({B, L, d}));
}

void CausalSelfAttentionImpl::append_kv(const torch::Tensor& x, KVCache& cache, int layer) {
  const int64_t B = x.size(0), L = x.size(1), hd = d / heads, offset = cache.length;
  TORCH_CHECK(offset + L <= cache.capacity(), "KV cache overflow: ", offset, " + ", L, " > ", cache.capacity());
  // The key and value rows of the qkv projection only (its first d outputs are the queries).
  auto kv = F::linear(x, qkv->weight.narrow(0, d, 2 * d), qkv->bias.narrow(0, d, 2 * d))
                .view({B, L, 2, heads, hd})
                .permute({2, 0, 3, 1, 4});  // [2, B, H, L, hd]
  cache.k[static_cast<size_t>(layer)].narrow(3, offset, L).copy_(kv[0].transpose(2, 3));
  cache.v[static_cast<size_t>(layer)].narrow(2, offset, L).copy_(kv[1]);
}

BlockImpl::BlockImpl(int64_t d, int64_t heads) {
  ln1 = register_module("ln1", torch::nn::LayerNorm(torch::nn::LayerNormOptions({d})));
  attn = register_module("attn", CausalSelfAttention(d, heads));
  ln2 = register_module("ln2", torch::nn::LayerNorm(torch::nn::LayerNormOptions({d})));
  fc = register_module("fc", torch::nn::Linear(d, 4 * d));
  fc_proj = register_module("fc_proj", torch::nn::Linear(4 * d, d));
}

torch::Tensor BlockImpl::forward(const torch::Tensor& x, KVCache* cache, int layer) {
  if (cache && x.size(1) == 1) {  // one token per row (sampling): the MLP on 2-D rows, see attention above
    const int64_t B = x.size(0), d = x.size(2);
    auto h = (x + attn->forward(ln1->forward(x), cache, layer)).view({B, d});
    return (h + fc_proj->forward(F::gelu(fc->forward(ln2->forward(h))))).view({B, 1, d});
  }
  auto h = x + attn->forward(ln1->forward(x), cache, layer);
  return h + fc_proj->forward(F::gelu(fc->forward(ln2->forward(h))));
}

namespace {

// The block is not an input of the autograd node, so its parameter gradients are accumulated by the nested backward
// in backward(); only the gradient of x is returned (the "reentrant" checkpoint of PyTorch).
struct CheckpointFn : torch::autograd::Function<CheckpointFn> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::Tensor x, BlockImpl* block) {
    ctx->saved_data["block"] = reinterpret_cast<int64_t>(block);
    ctx->save_for_backward({x});
    torch::NoGradGuard ng;
    return block->forward(x);
  }
  static torch::autograd::tensor_list backward(torch::autograd::AutogradContext* ctx,
                                               torch::autograd::tensor_list grad) {
    auto* block = reinterpret_cast<BlockImpl*>(ctx->saved_data["block"].toInt());
    auto x = ctx->get_saved_variables()[0].detach().requires_grad_(true);
    {
      torch::AutoGradMode on(true);
      auto y = block->forward(x);
      y.backward(grad[0]);
    }
    return {x.grad(), torch::Tensor()};
  }
};

}  // namespace

torch::Tensor checkpointed(Block& block, const torch::Tensor& x) {
  if (!torch::GradMode::is_enabled() || !x.requires_grad()) return block->forward(x);
  return CheckpointFn::apply(x, block.get());
}

}  // namespace gaia::world
