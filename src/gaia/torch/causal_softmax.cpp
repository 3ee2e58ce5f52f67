#include "gaia/torch/causal_softmax.h"

#include <cstring>
#include <limits>
#include <vector>

#include <ATen/Parallel.h>

#include "gaia/core/error.h"
#include "gaia/torch/exp8.h"
#include "gaia/torch/simd.h"

namespace gaia {

namespace {

using Shorts8 = uint16_t __attribute__((vector_size(16)));

// Eight values as floats (bf16: torch's kBFloat16, a float's upper 16 bits), and back (rounded to nearest even, as
// LibTorch rounds).
[[gnu::always_inline]] inline Floats8 load8(const float* p) {
  Floats8 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
[[gnu::always_inline]] inline Floats8 load8(const uint16_t* p) {
  Shorts8 s;
  std::memcpy(&s, p, sizeof s);
  return (Floats8)(__builtin_convertvector(s, Ints8) << 16);  // vector casts keep the bits
}
[[gnu::always_inline]] inline void store8(float* p, Floats8 v) { std::memcpy(p, &v, sizeof v); }
[[gnu::always_inline]] inline void store8(uint16_t* p, Floats8 v) {
  const Ints8 u = (Ints8)v;
  Ints8 r = (u + 0x7FFF + ((u >> 16) & 1)) >> 16;
  r = v != v ? Ints8{} + 0x7FC0 : r;  // NaN stays NaN
  const Shorts8 s = __builtin_convertvector(r, Shorts8);
  std::memcpy(p, &s, sizeof s);
}

// A row's first n values through eight-wide steps; the tail of fewer than eight is padded with `pad` on reading and
// not written.
template <class T>
[[gnu::always_inline]] inline Floats8 read8(const T* p, int64_t j, int64_t n, float pad) {
  if (j + 8 <= n) return load8(p + j);
  T tmp[8];
  Floats8 v = Floats8{} + pad;
  const int64_t k = n - j;
  std::memcpy(tmp, p + j, sizeof(T) * size_t(k));
  const Floats8 w = load8(tmp);
  for (int64_t e = 0; e < k; ++e) v[e] = w[e];
  return v;
}
template <class T>
[[gnu::always_inline]] inline void write8(T* p, int64_t j, int64_t n, Floats8 v) {
  if (j + 8 <= n) return store8(p + j, v);
  T tmp[8];
  store8(tmp, v);
  std::memcpy(p + j, tmp, sizeof(T) * size_t(n - j));
}

[[gnu::always_inline]] inline float sum8(Floats8 v) {
  float s = 0;
  for (int e = 0; e < 8; ++e) s += v[e];
  return s;
}

// Rows [r0, r1) of the [N, L, L] squares; row r is query i = r % L, which sees keys 0 .. i.
template <class T>
[[gnu::always_inline]] inline void forward_of(const T* s, T* p, int64_t r0, int64_t r1, int64_t L, float scale,
                                              float* buf) {
  constexpr float kLowest = -std::numeric_limits<float>::infinity();
  for (int64_t r = r0; r < r1; ++r) {
    const T* x = s + r * L;
    T* y = p + r * L;
    const int64_t n = r % L + 1;
    Floats8 top8 = Floats8{} + kLowest;
    for (int64_t j = 0; j < n; j += 8) {
      const Floats8 v = read8(x, j, n, kLowest);
      top8 = v > top8 ? v : top8;
    }
    float top = kLowest;
    for (int e = 0; e < 8; ++e) top = top8[e] > top ? top8[e] : top;
    top *= scale;  // scale > 0
    Floats8 total{};
    for (int64_t j = 0; j < n; j += 8) {  // buf holds L rounded up to eight floats
      Floats8 e = exp8(read8(x, j, n, kLowest) * scale - top);
      if (j + 8 > n)
        for (int64_t k = n - j; k < 8; ++k) e[k] = 0;
      total += e;
      store8(buf + j, e);
    }
    const float inv = 1.0f / sum8(total);
    for (int64_t j = 0; j < n; j += 8) write8(y, j, n, load8(buf + j) * inv);
    std::memset(static_cast<void*>(y + n), 0, sizeof(T) * size_t(L - n));
  }
}

// ds_j = scale p_j (g_j - sum_k p_k g_k) over the keys a query sees; 0 after them.
template <class T>
[[gnu::always_inline]] inline void backward_of(const T* p, const T* g, T* ds, int64_t r0, int64_t r1, int64_t L,
                                               float scale) {
  for (int64_t r = r0; r < r1; ++r) {
    const T *pr = p + r * L, *gr = g + r * L;
    T* d = ds + r * L;
    const int64_t n = r % L + 1;
    Floats8 dot8{};
    for (int64_t j = 0; j < n; j += 8) dot8 += read8(pr, j, n, 0) * read8(gr, j, n, 0);
    const float dot = sum8(dot8);
    for (int64_t j = 0; j < n; j += 8) write8(d, j, n, (read8(gr, j, n, 0) - dot) * read8(pr, j, n, 0) * scale);
    std::memset(static_cast<void*>(d + n), 0, sizeof(T) * size_t(L - n));
  }
}

GAIA_SIMD_CLONES void forward_rows(const float* s, float* p, int64_t r0, int64_t r1, int64_t L, float scale,
                                   float* buf) {
  forward_of(s, p, r0, r1, L, scale, buf);
}
GAIA_SIMD_CLONES void forward_rows(const uint16_t* s, uint16_t* p, int64_t r0, int64_t r1, int64_t L, float scale,
                                   float* buf) {
  forward_of(s, p, r0, r1, L, scale, buf);
}
GAIA_SIMD_CLONES void backward_rows(const float* p, const float* g, float* ds, int64_t r0, int64_t r1, int64_t L,
                                    float scale) {
  backward_of(p, g, ds, r0, r1, L, scale);
}
GAIA_SIMD_CLONES void backward_rows(const uint16_t* p, const uint16_t* g, uint16_t* ds, int64_t r0, int64_t r1,
                                    int64_t L, float scale) {
  backward_of(p, g, ds, r0, r1, L, scale);
}

template <class T>
const T* raw(const torch::Tensor& t) {
  return static_cast<const T*>(t.data_ptr());
}
template <class T>
T* raw_out(torch::Tensor& t) {
  return static_cast<T*>(t.data_ptr());
}

// Rows per task: a few hundred KB of scores.
constexpr int64_t kGrain = 64;

torch::Tensor forward_kernel(const torch::Tensor& s, double scale) {
  auto p = torch::empty_like(s);
  const int64_t L = s.size(2), rows = s.size(0) * L;
  const bool half = s.scalar_type() == torch::kBFloat16;
  at::parallel_for(0, rows, kGrain, [&](int64_t r0, int64_t r1) {
    thread_local std::vector<float> buf;
    buf.resize(size_t((L + 7) / 8 * 8));
    if (half) forward_rows(raw<uint16_t>(s), raw_out<uint16_t>(p), r0, r1, L, float(scale), buf.data());
    else forward_rows(raw<float>(s), raw_out<float>(p), r0, r1, L, float(scale), buf.data());
  });
  return p;
}

torch::Tensor backward_kernel(const torch::Tensor& p, const torch::Tensor& g, double scale) {
  auto ds = torch::empty_like(p);
  const int64_t L = p.size(2), rows = p.size(0) * L;
  const bool half = p.scalar_type() == torch::kBFloat16;
  at::parallel_for(0, rows, kGrain, [&](int64_t r0, int64_t r1) {
    if (half) backward_rows(raw<uint16_t>(p), raw<uint16_t>(g), raw_out<uint16_t>(ds), r0, r1, L, float(scale));
    else backward_rows(raw<float>(p), raw<float>(g), raw_out<float>(ds), r0, r1, L, float(scale));
  });
  return ds;
}

struct CausalSoftmaxFunction : torch::autograd::Function<CausalSoftmaxFunction> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& s, double scale) {
    auto p = forward_kernel(s, scale);
    ctx->save_for_backward({p});
    ctx->saved_data["scale"] = scale;
    return p;
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto p = ctx->get_saved_variables()[0];
    const auto g = grads[0].to(p.scalar_type()).contiguous();
    return {backward_kernel(p, g, ctx->saved_data["scale"].toDouble()), torch::Tensor()};
  }
};

}  // namespace

bool causal_softmax_applies(const torch::Tensor& s) {
  return s.device().is_cpu() && s.dim() == 3 && s.size(1) == s.size(2) && s.is_contiguous() &&
         (s.scalar_type() == torch::kFloat || s.scalar_type() == torch::kBFloat16);
}

torch::Tensor causal_softmax(const torch::Tensor& scores, double scale) {
  if (!causal_softmax_applies(scores))
    fail("causal_softmax: square float32 or bf16 scores [N, L, L], contiguous on the CPU, expected");
  if (!(scale > 0)) fail("causal_softmax: scale must be > 0, got {}", scale);
  return CausalSoftmaxFunction::apply(scores, scale);
}

}  // namespace gaia
