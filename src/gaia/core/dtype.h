#pragma once
// Element types shared by the safetensors and .npy formats (and mapped to torch dtypes in gaia/torch).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace gaia {

enum class DType { F64, F32, F16, BF16, I64, I32, I16, I8, U8, BOOL };

size_t dtype_size(DType t);
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
