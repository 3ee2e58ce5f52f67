#include "gaia/core/dtype.h"

#include <cstring>
#include <limits>
#include <type_traits>

#include <fmt/format.h>

#include "gaia/core/error.h"

namespace gaia {

size_t dtype_size(DType t) {
  switch (t) {
    case DType::F64: case DType::I64: case DType::U64: return 8;
    case DType::F32: case DType::I32: case DType::U32: return 4;
    case DType::F16: case DType::BF16: case DType::I16: case DType::U16: return 2;
    case DType::I8: case DType::U8: case DType::BOOL: return 1;
  }
  return 0;
}

namespace {
struct Name { DType t; const char* s; };
constexpr Name kNames[] = {{DType::F64, "F64"}, {DType::F32, "F32"}, {DType::F16, "F16"},
                           {DType::BF16, "BF16"}, {DType::I64, "I64"}, {DType::I32, "I32"},
                           {DType::I16, "I16"}, {DType::I8, "I8"}, {DType::U8, "U8"},
                           {DType::U16, "U16"}, {DType::U32, "U32"}, {DType::U64, "U64"},
                           {DType::BOOL, "BOOL"}};

template <typename T> int64_t load(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  if constexpr (std::is_same_v<T, uint64_t>)
    return v > uint64_t(std::numeric_limits<int64_t>::max()) ? std::numeric_limits<int64_t>::max() : int64_t(v);
  else
    return static_cast<int64_t>(v);
}
}  // namespace

bool is_integer(DType t) { return t != DType::F64 && t != DType::F32 && t != DType::F16 && t != DType::BF16; }

std::vector<int64_t> integer_values(DType t, const uint8_t* data, size_t n) {
  if (!is_integer(t)) fail("an array of {} is not an integer array", safetensors_name(t));
  std::vector<int64_t> out(n);
  const size_t s = dtype_size(t);
  for (size_t i = 0; i < n; ++i) {
    const uint8_t* p = data + i * s;
    switch (t) {
      case DType::I64: out[i] = load<int64_t>(p); break;
      case DType::I32: out[i] = load<int32_t>(p); break;
      case DType::I16: out[i] = load<int16_t>(p); break;
      case DType::I8: out[i] = load<int8_t>(p); break;
      case DType::U64: out[i] = load<uint64_t>(p); break;
      case DType::U32: out[i] = load<uint32_t>(p); break;
      case DType::U16: out[i] = load<uint16_t>(p); break;
      default: out[i] = load<uint8_t>(p); break;  // U8, BOOL
    }
  }
  return out;
}

std::string safetensors_name(DType t) {
  for (auto& n : kNames) if (n.t == t) return n.s;
  return "?";
}

bool dtype_from_safetensors(const std::string& s, DType* out) {
  for (auto& n : kNames)
    if (s == n.s) { *out = n.t; return true; }
  return false;
}

int64_t numel(const std::vector<int64_t>& shape) {
  int64_t n = 1;
  // Shapes come from file headers: a product that overflows must fail, not wrap to a size that passes the checks.
  for (auto d : shape)
    if (__builtin_mul_overflow(n, d, &n)) fail("shape {} has more elements than int64 can count", shape_str(shape));
  return n;
}

std::string shape_str(const std::vector<int64_t>& shape) { return fmt::format("[{}]", fmt::join(shape, ", ")); }

uint16_t float_to_half(float f) {
  uint32_t x;
  std::memcpy(&x, &f, 4);
  uint32_t sign = (x >> 16) & 0x8000u;
  int32_t exp = static_cast<int32_t>((x >> 23) & 0xff) - 127 + 15;
  uint32_t mant = x & 0x7fffffu;
  if (((x >> 23) & 0xff) == 0xff) return static_cast<uint16_t>(sign | 0x7c00u | (mant ? 0x200u : 0));  // inf/nan
  if (exp >= 31) return static_cast<uint16_t>(sign | 0x7c00u);                                       // overflow
  if (exp <= 0) {                                                                                     // subnormal
    if (exp < -10) return static_cast<uint16_t>(sign);
    mant |= 0x800000u;
    uint32_t shift = static_cast<uint32_t>(14 - exp);
    uint32_t h = mant >> shift;
    uint32_t rem = mant & ((1u << shift) - 1), half = 1u << (shift - 1);
    if (rem > half || (rem == half && (h & 1u))) ++h;
    return static_cast<uint16_t>(sign | h);
  }
  uint32_t h = sign | (static_cast<uint32_t>(exp) << 10) | (mant >> 13);
  uint32_t rem = mant & 0x1fffu;
  if (rem > 0x1000u || (rem == 0x1000u && (h & 1u))) ++h;  // may carry into exponent: correct behaviour
  return static_cast<uint16_t>(h);
}

float half_to_float(uint16_t h) {
  uint32_t sign = (h & 0x8000u) << 16, exp = (h >> 10) & 0x1f, mant = h & 0x3ffu, x;
  if (exp == 0) {
    if (mant == 0) x = sign;
    else {
      exp = 127 - 15 + 1;
      while (!(mant & 0x400u)) { mant <<= 1; --exp; }
      x = sign | (exp << 23) | ((mant & 0x3ffu) << 13);
    }
  } else if (exp == 31) {
    x = sign | 0x7f800000u | (mant << 13);
  } else {
    x = sign | ((exp - 15 + 127) << 23) | (mant << 13);
  }
  float f;
  std::memcpy(&f, &x, 4);
  return f;
}

uint16_t float_to_bf16(float f) {
  uint32_t x;
  std::memcpy(&x, &f, 4);
  if ((x & 0x7fffffffu) > 0x7f800000u) return static_cast<uint16_t>((x >> 16) | 0x40u);  // quiet NaN
  x += 0x7fffu + ((x >> 16) & 1u);
  return static_cast<uint16_t>(x >> 16);
}

float bf16_to_float(uint16_t b) {
  uint32_t x = static_cast<uint32_t>(b) << 16;
  float f;
  std::memcpy(&f, &x, 4);
  return f;
}

}  // namespace gaia
