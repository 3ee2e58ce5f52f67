// The machine's peak arithmetic, measured (docs/benchmarks.md, "Training against the machine's peak"): chains of
// independent fused multiply-adds that never touch memory, per thread, at the widest vectors the CPU runs:
// float32 FMA (AVX-512: 16 lanes x 2 FLOPs; AVX2: 8 x 2) and the bf16 dot product (AVX512_BF16 vdpbf16ps: 16 lanes
// x 2 products x 2 FLOPs). The figure a step's FLOPs are held against: what one core does at most, times the cores.
#include <benchmark/benchmark.h>

#include <immintrin.h>

namespace {

constexpr int kChains = 12;  // independent accumulators: enough to cover the FMA latency on two ports
constexpr int64_t kIterations = 1 << 16;

__attribute__((target("avx512f"))) float fma512(float seed) {
  __m512 acc[kChains];
  for (int c = 0; c < kChains; ++c) acc[c] = _mm512_set1_ps(seed + float(c));
  const __m512 a = _mm512_set1_ps(0.999f), b = _mm512_set1_ps(1e-4f);
  for (int64_t i = 0; i < kIterations; ++i)
    for (int c = 0; c < kChains; ++c) acc[c] = _mm512_fmadd_ps(acc[c], a, b);
  __m512 s = acc[0];
  for (int c = 1; c < kChains; ++c) s = _mm512_add_ps(s, acc[c]);
  return _mm512_reduce_add_ps(s);
}

__attribute__((target("avx2,fma"))) float fma256(float seed) {
  __m256 acc[kChains];
  for (int c = 0; c < kChains; ++c) acc[c] = _mm256_set1_ps(seed + float(c));
  const __m256 a = _mm256_set1_ps(0.999f), b = _mm256_set1_ps(1e-4f);
  for (int64_t i = 0; i < kIterations; ++i)
    for (int c = 0; c < kChains; ++c) acc[c] = _mm256_fmadd_ps(acc[c], a, b);
  __m256 s = acc[0];
  for (int c = 1; c < kChains; ++c) s = _mm256_add_ps(s, acc[c]);
  float out[8];
  _mm256_storeu_ps(out, s);
  return out[0];
}

__attribute__((target("avx512f,avx512bf16"))) float dot_bf16(float seed) {
  __m512 acc[kChains];
  for (int c = 0; c < kChains; ++c) acc[c] = _mm512_set1_ps(seed + float(c));
  const __m512bh a = (__m512bh)_mm512_set1_epi16(0x3f80), b = (__m512bh)_mm512_set1_epi16(0x3880);  // 1, 2^-14
  for (int64_t i = 0; i < kIterations; ++i)
    for (int c = 0; c < kChains; ++c) acc[c] = _mm512_dpbf16_ps(acc[c], a, b);
  __m512 s = acc[0];
  for (int c = 1; c < kChains; ++c) s = _mm512_add_ps(s, acc[c]);
  return _mm512_reduce_add_ps(s);
}

// Arg: 0 float32 FMA AVX-512, 1 float32 FMA AVX2, 2 bf16 dot products AVX512_BF16.
void BM_Peak(benchmark::State& st) {
  const int kind = int(st.range(0));
  __builtin_cpu_init();
  const bool ok = kind == 0   ? __builtin_cpu_supports("avx512f")
                  : kind == 1 ? __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")
                              : __builtin_cpu_supports("avx512bf16");
  if (!ok) {
    st.SkipWithError("this CPU lacks the instructions");
    return;
  }
  const double flops_per_op = kind == 0 ? 32 : kind == 1 ? 16 : 64;
  float sink = 0;
  for (auto _ : st) sink += kind == 0 ? fma512(sink) : kind == 1 ? fma256(sink) : dot_bf16(sink);
  benchmark::DoNotOptimize(sink);
  st.counters["FLOP/s"] = benchmark::Counter(flops_per_op * kChains * double(kIterations) * double(st.iterations()),
                                              benchmark::Counter::kIsRate, benchmark::Counter::kIs1000);
  st.SetLabel(kind == 0 ? "fp32 FMA, AVX-512" : kind == 1 ? "fp32 FMA, AVX2" : "bf16 dot product, AVX512_BF16");
}
BENCHMARK(BM_Peak)->Arg(0)->Arg(1)->Arg(2)->ThreadRange(1, 2)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
