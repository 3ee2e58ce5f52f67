#pragma once
// Hot inner loops compiled for AVX2 as well as the baseline x86-64 ISA where the compiler supports function
// multiversioning (the clone is picked at load time; the build stays portable).
#include <cstdint>
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__) && __GNUC__ >= 12
// x86-64-v3: AVX2 with FMA, a multiply-add in one instruction ("avx2" alone leaves them apart). An ISA level, not a
// CPU model, so every CPU that has it takes the clone (arch=haswell would test for that very model).
#define GAIA_SIMD_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#elif defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
#define GAIA_SIMD_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define GAIA_SIMD_CLONES
#endif

namespace gaia {
// Outputs a hot loop keeps in registers across its inner products: eight AVX2 registers of floats.
constexpr int64_t kSimdLanes = 64;
}  // namespace gaia
