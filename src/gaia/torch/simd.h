#pragma once
// Hot inner loops compiled for AVX2 as well as the baseline x86-64 ISA where the compiler supports function
// multiversioning (the clone is picked at load time; the build stays portable).
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
#define GAIA_SIMD_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define GAIA_SIMD_CLONES
#endif
