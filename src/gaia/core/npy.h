#pragma once
// NumPy .npy (format versions 1.0-3.0) for C-order arrays of int16/int32/int64/uint8/float32/float64/bool.
// Token arrays made by other tokenizers (e.g. [frames, 8, 16] int16) load through this as token datasets.
#include <cstring>
#include <string>
#include <vector>

#include "gaia/core/dtype.h"
#include "gaia/core/fs.h"

namespace gaia {

struct NpyArray {
  DType dtype = DType::F32;
  std::vector<int64_t> shape;
  std::vector<uint8_t> bytes;  // little-endian, C order

  int64_t size() const { return numel(shape); }
  template <typename T> const T* as() const { return reinterpret_cast<const T*>(bytes.data()); }
  template <typename T> T* as() { return reinterpret_cast<T*>(bytes.data()); }
  // Values converted to int64 / double whatever the stored integer / float type.
  std::vector<int64_t> to_int64() const;
  std::vector<double> to_double() const;
};

NpyArray npy_read(const fs::path& path);  // throws gaia::Error naming the file on bad magic, dtype, size
void npy_write(const fs::path& path, const NpyArray& a);  // atomic

template <typename T> NpyArray npy_make(DType t, std::vector<int64_t> shape, const std::vector<T>& v) {
  NpyArray a;
  a.dtype = t;
  a.shape = std::move(shape);
  a.bytes.resize(v.size() * sizeof(T));
  if (!v.empty()) std::memcpy(a.bytes.data(), v.data(), a.bytes.size());
  return a;
}

}  // namespace gaia
