#pragma once
// exp of eight floats at once for softmax rows (shifted scores, x <= 0), as Cephes' expf: x = n ln2 + r, exp(r) by a
// polynomial, 2^n from the exponent bits; below -87.3 it gives 2^-126 (a weight of no account next to the row's
// maximum, 1). Inline, so each SIMD clone of a caller (torch/simd.h) compiles it for its own ISA.
#include <cstdint>

namespace gaia {

using Floats8 = float __attribute__((vector_size(32)));
using Ints8 = int32_t __attribute__((vector_size(32)));

[[gnu::always_inline]] inline Floats8 exp8(Floats8 x) {
  const Floats8 lo = Floats8{} - 87.33654f;
  x = x < lo ? lo : x;
  const Floats8 t = x * 1.44269504088896341f + 12582912.0f;  // + 1.5 * 2^23: n = round(x / ln2) in the low bits
  const Floats8 n = t - 12582912.0f;
  const Ints8 ni = (Ints8)t - 0x4B400000;  // a vector cast: the same bits
  const Floats8 r = (x - n * 0.693359375f) - n * -2.12194440e-4f;
  Floats8 p = r * 1.9875691500e-4f + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  const Floats8 y = p * r * r + r + 1.0f;
  const Ints8 e = (ni + 127) << 23;
  return y * (Floats8)e;
}

}  // namespace gaia
