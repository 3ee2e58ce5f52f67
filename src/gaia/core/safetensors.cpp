#include "gaia/core/safetensors.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <nlohmann/json.hpp>

#include "gaia/core/error.h"

namespace gaia {

using nlohmann::json;

namespace {
constexpr uint64_t kMaxHeader = 100ull * 1024 * 1024;  // the reference implementation's limit
}

SafetensorsFile::SafetensorsFile(const fs::path& path) {
  if (!fs::exists(path)) fail("{}: no such file", path.string());
  file_ = std::make_shared<MappedFile>(path);
  const std::string p = path.string();
  const size_t size = file_->size();
  if (size < 8) fail("{}: truncated safetensors file ({} bytes, no header length)", p, size);
  uint64_t n = 0;
  for (int i = 7; i >= 0; --i) n = (n << 8) | file_->data()[i];
  if (n > kMaxHeader) fail("{}: safetensors header length {} is implausible (corrupt file?)", p, n);
  if (8 + n > size) fail("{}: truncated safetensors file (header says {} bytes, file has {})", p, 8 + n, size);
  json header;
  try {
    header = json::parse(file_->data() + 8, file_->data() + 8 + n);
  } catch (const std::exception& e) {
    fail("{}: safetensors header is not valid JSON ({})", p, e.what());
  }
  if (!header.is_object()) fail("{}: safetensors header is not a JSON object", p);
  const size_t data_size = size - 8 - n;
  const uint8_t* base = file_->data() + 8 + n;
  std::vector<std::pair<size_t, size_t>> ranges;
  for (auto& [name, v] : header.items()) {
    if (name == "__metadata__") {
      if (!v.is_object()) fail("{}: __metadata__ must be an object of strings", p);
      for (auto& [k, s] : v.items()) {
        if (!s.is_string()) fail("{}: __metadata__[{}] must be a string", p, k);
        metadata_[k] = s.get<std::string>();
      }
      continue;
    }
    if (!v.is_object() || !v.contains("dtype") || !v.contains("shape") || !v.contains("data_offsets"))
      fail("{}: tensor '{}' needs dtype, shape and data_offsets", p, name);
    TensorView t;
    if (!v["dtype"].is_string() || !dtype_from_safetensors(v["dtype"].get<std::string>(), &t.dtype))
      fail("{}: tensor '{}' has unsupported dtype {}", p, name, v["dtype"].dump());
    if (!v["shape"].is_array()) fail("{}: tensor '{}' shape is not an array", p, name);
    for (auto& d : v["shape"]) {
      if (!d.is_number_integer() || d.get<int64_t>() < 0) fail("{}: tensor '{}' has a bad shape {}", p, name, v["shape"].dump());
      t.shape.push_back(d.get<int64_t>());
    }
    auto& off = v["data_offsets"];
    if (!off.is_array() || off.size() != 2 || !off[0].is_number_unsigned() || !off[1].is_number_unsigned())
      fail("{}: tensor '{}' data_offsets must be [begin, end]", p, name);
    size_t b = off[0].get<size_t>(), e = off[1].get<size_t>();
    if (b > e || e > data_size)
      fail("{}: tensor '{}' data_offsets [{}, {}] outside the data section ({} bytes; truncated file?)", p, name, b, e, data_size);
    size_t expect = 0;
    if (__builtin_mul_overflow(static_cast<size_t>(numel(t.shape)), dtype_size(t.dtype), &expect))
      fail("{}: tensor '{}' shape {} is too large", p, name, v["shape"].dump());
    if (e - b != expect)
      fail("{}: tensor '{}' has {} bytes but shape {} of {} needs {}", p, name, e - b, shape_str(t.shape),
           safetensors_name(t.dtype), expect);
    t.data = base + b;
    t.nbytes = e - b;
    ranges.emplace_back(b, e);
    tensors_[name] = t;
  }
  // Tensors must tile the data section without gaps or overlaps (as the reference validator requires).
  std::sort(ranges.begin(), ranges.end());
  size_t cursor = 0;
  for (auto& [b, e] : ranges) {
    if (b != cursor) fail("{}: tensor data overlaps or leaves a gap at byte {}", p, b);
    cursor = e;
  }
  if (cursor != data_size) fail("{}: {} trailing bytes after the last tensor", p, data_size - cursor);
}

const TensorView& SafetensorsFile::get(const std::string& name) const {
  auto it = tensors_.find(name);
  if (it == tensors_.end()) fail("{}: no tensor named '{}'", path().string(), name);
  return it->second;
}

std::vector<std::string> SafetensorsFile::names() const {
  std::vector<std::string> out;
  for (auto& kv : tensors_) out.push_back(kv.first);
  return out;
}

std::vector<float> SafetensorsFile::to_float(const std::string& name) const {
  const TensorView& t = get(name);
  size_t n = static_cast<size_t>(numel(t.shape));
  std::vector<float> out(n);
  switch (t.dtype) {
    case DType::F32: std::memcpy(out.data(), t.data, n * 4); break;
    case DType::F64:
      for (size_t i = 0; i < n; ++i) { double d; std::memcpy(&d, t.data + 8 * i, 8); out[i] = static_cast<float>(d); }
      break;
    case DType::F16:
      for (size_t i = 0; i < n; ++i) { uint16_t h; std::memcpy(&h, t.data + 2 * i, 2); out[i] = half_to_float(h); }
      break;
    case DType::BF16:
      for (size_t i = 0; i < n; ++i) { uint16_t h; std::memcpy(&h, t.data + 2 * i, 2); out[i] = bf16_to_float(h); }
      break;
    default: fail("{}: tensor '{}' is {}, not a float type", path().string(), name, safetensors_name(t.dtype));
  }
  return out;
}

void SafetensorsWriter::add(const std::string& name, DType dtype, std::vector<int64_t> shape, const void* data,
                            size_t nbytes) {
  if (name == "__metadata__") fail("safetensors: '__metadata__' is reserved and cannot name a tensor");
  size_t expect = static_cast<size_t>(numel(shape)) * dtype_size(dtype);
  if (nbytes != expect) fail("safetensors: tensor '{}' has {} bytes, shape {} needs {}", name, nbytes, shape_str(shape), expect);
  entries_[name] = Entry{dtype, std::move(shape), std::string(static_cast<const char*>(data), nbytes)};
}

void SafetensorsWriter::add_f32(const std::string& name, std::vector<int64_t> shape, const std::vector<float>& v) {
  add(name, DType::F32, std::move(shape), v.data(), v.size() * sizeof(float));
}

std::string SafetensorsWriter::serialize() const {
  json header = json::object();
  size_t off = 0;
  for (auto& [name, e] : entries_) {
    header[name] = {{"dtype", safetensors_name(e.dtype)}, {"shape", e.shape}, {"data_offsets", {off, off + e.bytes.size()}}};
    off += e.bytes.size();
  }
  if (!metadata_.empty()) header["__metadata__"] = metadata_;
  std::string h = header.dump();
  while ((8 + h.size()) % 8 != 0) h.push_back(' ');  // align the data section to 8 bytes, as HF does
  std::string out;
  out.reserve(8 + h.size() + off);
  uint64_t n = h.size();
  for (int i = 0; i < 8; ++i) out.push_back(static_cast<char>((n >> (8 * i)) & 0xff));
  out += h;
  for (auto& [name, e] : entries_) out += e.bytes;
  return out;
}

void SafetensorsWriter::write(const fs::path& path) const { write_file_atomic(path, serialize()); }

double rewrite_weights(const fs::path& in, const fs::path& out, bool half,
                       const std::map<std::string, std::string>& metadata) {
  SafetensorsWriter w;
  double max_err = 0;
  {
    SafetensorsFile f(in);
    for (const auto& [k, v] : f.metadata()) w.set_metadata(k, v);
    for (const auto& [k, v] : metadata) w.set_metadata(k, v);
    for (const auto& name : f.names()) {
      const auto& t = f.get(name);
      if (!half || t.dtype != DType::F32) {
        w.add(name, t.dtype, t.shape, t.data, t.nbytes);
        continue;
      }
      auto vals = f.to_float(name);
      std::vector<uint16_t> h(vals.size());
      for (size_t i = 0; i < vals.size(); ++i) {
        if (!std::isfinite(vals[i])) fail("{}: tensor '{}' holds a non-finite value", in.string(), name);
        h[i] = float_to_half(vals[i]);
        max_err = std::max(max_err, double(std::abs(half_to_float(h[i]) - vals[i])));
      }
      w.add(name, DType::F16, t.shape, h.data(), h.size() * sizeof(uint16_t));
    }
  }  // the input mapping is closed before the output (possibly the same path) is renamed into place
  w.write(out);
  return max_err;
}

}  // namespace gaia
