#pragma once
// safetensors (Hugging Face format): 8-byte little-endian header length N, N bytes of JSON
// {"name": {"dtype": "F32", "shape": [..], "data_offsets": [begin, end]}, "__metadata__": {str: str}},
// then the raw little-endian tensor bytes. Files are memory-mapped on read; the header is validated strictly
// (offsets in range, contiguous, non-overlapping, sizes = numel * dtype size) so a corrupt file fails early
// with a message that names the file and the tensor.
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "gaia/core/dtype.h"
#include "gaia/core/fs.h"

namespace gaia {

struct TensorView {
  DType dtype = DType::F32;
  std::vector<int64_t> shape;
  const uint8_t* data = nullptr;  // points into the mapped file (or a writer's buffer)
  size_t nbytes = 0;
};

class SafetensorsFile {
 public:
  explicit SafetensorsFile(const fs::path& path);  // throws gaia::Error naming the file on any problem
  bool contains(const std::string& name) const { return tensors_.count(name) > 0; }
  const TensorView& get(const std::string& name) const;  // throws naming the missing tensor
  std::vector<std::string> names() const;                // sorted
  const std::map<std::string, std::string>& metadata() const { return metadata_; }
  const fs::path& path() const { return file_->path(); }
  // Reads a tensor as float32 values whatever its float dtype (F32/F16/BF16/F64).
  std::vector<float> to_float(const std::string& name) const;

 private:
  std::shared_ptr<MappedFile> file_;
  std::map<std::string, TensorView> tensors_;
  std::map<std::string, std::string> metadata_;
};

// Accumulates tensors and writes them atomically. Tensor data is copied at add() time.
class SafetensorsWriter {
 public:
  void add(const std::string& name, DType dtype, std::vector<int64_t> shape, const void* data, size_t nbytes);
  void add_f32(const std::string& name, std::vector<int64_t> shape, const std::vector<float>& values);
  void set_metadata(const std::string& key, const std::string& value) { metadata_[key] = value; }
  void write(const fs::path& path) const;
  std::string serialize() const;

 private:
  struct Entry { DType dtype; std::vector<int64_t> shape; std::string bytes; };
  std::map<std::string, Entry> entries_;  // sorted by name, like the reference implementation
  std::map<std::string, std::string> metadata_;
};

// Re-writes a weights file: with `half`, every F32 tensor stored as F16 (other dtypes unchanged), for shipping models
// at half the size (gaia's loaders convert back to float32); the metadata entries in `metadata` replace or join the
// file's own. Returns the largest absolute rounding error (0 without `half`), so the caller can say what was lost.
// Written atomically; `in` and `out` may be the same path.
double rewrite_weights(const fs::path& in, const fs::path& out, bool half,
                       const std::map<std::string, std::string>& metadata = {});
inline double convert_to_half(const fs::path& in, const fs::path& out) { return rewrite_weights(in, out, true); }

}  // namespace gaia
