#pragma once
// Element types shared by the safetensors and .npy formats (and mapped to torch dtypes in gaia/torch).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace gaia {

enum class DType { F64, F32, F16, BF16, I64, I32, I16, I8, U8, U16, U32, U64, BOOL };

size_t dtype_size(DType t);
bool is_integer(DType t);  // the signed and unsigned integer types and BOOL
// n values of an integer dtype at `data` (little-endian) as int64; uint64 values beyond int64 become INT64_MAX.
// Fails naming the dtype for a float type.
std::vector<int64_t> integer_values(DType t, const uint8_t* data, size_t n);
std::string safetensors_name(DType t);              // "F32", "BF16", ...
bool dtype_from_safetensors(const std::string& s, DType* out);

// Row-major shape helpers.
int64_t numel(const std::vector<int64_t>& shape);
std::string shape_str(const std::vector<int64_t>& shape);  // "[3, 72, 128]"

// IEEE half / bfloat16 conversions (round to nearest even), used when writing fp16 weights without torch.
uint16_t float_to_half(float f);
float half_to_float(uint16_t h);
uint16_t float_to_bf16(float f);
float bf16_to_float(uint16_t b);

}  // namespace gaia
