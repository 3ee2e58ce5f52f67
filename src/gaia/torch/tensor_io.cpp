#include "gaia/torch/tensor_io.h"

#include <dlfcn.h>
#include <malloc.h>

#include <regex>
#include <thread>

#include "gaia/core/error.h"
#include "gaia/core/npy.h"
#include "gaia/torch/openblas.h"

namespace gaia {

namespace {
// Every program that links gaia's model code (gaia-core, the tests, the benchmarks, the Python module) runs
// OpenBLAS's kernels for this CPU: here, as the program or module loads, after OpenBLAS and before any product.
[[maybe_unused]] const bool openblas_kernels = use_openblas_kernels_of_this_cpu();
}  // namespace

torch::Device parse_device(const std::string& s) {
  static const std::regex re("(cpu|cuda)(:([0-9]+))?");
  std::smatch m;
  if (!std::regex_match(s, m, re)) fail("device '{}': expected cpu, cuda or cuda:N", s);
  if (m[1] == "cuda") {
    if (!torch::cuda::is_available()) fail("device '{}': this build or machine has no CUDA; use --device cpu", s);
    int idx = m[3].matched ? std::stoi(m[3].str()) : 0;
    if (idx >= static_cast<int>(torch::cuda::device_count())) fail("device '{}': only {} CUDA devices", s, torch::cuda::device_count());
    return torch::Device(torch::kCUDA, static_cast<c10::DeviceIndex>(idx));
  }
  return torch::Device(torch::kCPU);
}

void set_torch_threads(int n) {
  if (n <= 0) n = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  torch::set_num_threads(n);
  // LibTorch sends matrix products to the system BLAS. With OpenBLAS (pthreads) it would otherwise start a thread
  // per core on top of LibTorch's own, so it is told the same count when present (looked up, not linked: the
  // reference BLAS has no such call).
  using SetThreads = void (*)(int);
  if (auto f = reinterpret_cast<SetThreads>(openblas_symbol("openblas_set_num_threads"))) f(n);
}

void configure_allocator() {
  mallopt(M_MMAP_MAX, 0);                 // every block from the heap (brk), reusable after free
  // Never shrink the heap: a training step's peak (its attention scores) is freed at the end of every step, and
  // any threshold below it returned those pages only for the next step to fault and clear them again.
  mallopt(M_TRIM_THRESHOLD, -1);
}

torch::Dtype to_torch(DType t) {
  switch (t) {
    case DType::F64: return torch::kFloat64;
    case DType::F32: return torch::kFloat32;
    case DType::F16: return torch::kFloat16;
    case DType::BF16: return torch::kBFloat16;
    case DType::I64: return torch::kInt64;
    case DType::I32: return torch::kInt32;
    case DType::I16: return torch::kInt16;
    case DType::I8: return torch::kInt8;
    case DType::U8: return torch::kUInt8;
    case DType::BOOL: return torch::kBool;
    case DType::U16: case DType::U32: case DType::U64: break;
  }
  fail("{} tensors have no LibTorch dtype", safetensors_name(t));
}

DType from_torch(torch::Dtype t) {
  switch (t) {
    case torch::kFloat64: return DType::F64;
    case torch::kFloat32: return DType::F32;
    case torch::kFloat16: return DType::F16;
    case torch::kBFloat16: return DType::BF16;
    case torch::kInt64: return DType::I64;
    case torch::kInt32: return DType::I32;
    case torch::kInt16: return DType::I16;
    case torch::kInt8: return DType::I8;
    case torch::kUInt8: return DType::U8;
    case torch::kBool: return DType::BOOL;
    default: fail("tensor dtype {} cannot be stored in safetensors", c10::toString(t));
  }
}

torch::Tensor tensor_from_view(const TensorView& v) {
  std::vector<int64_t> shape(v.shape.begin(), v.shape.end());
  auto t = torch::empty(shape, torch::TensorOptions().dtype(to_torch(v.dtype)));
  if (v.nbytes) std::memcpy(t.data_ptr(), v.data, v.nbytes);
  return t;
}

torch::Tensor read_float_array(const fs::path& file, const std::string& name) {
  if (!fs::exists(file)) fail("{}: no such file", file.string());
  torch::Tensor t;
  const std::string ext = file.extension().string();
  if (ext == ".npy") {
    NpyArray a = npy_read(file);
    t = torch::empty(a.shape, torch::TensorOptions().dtype(to_torch(a.dtype)));
    if (!a.bytes.empty()) std::memcpy(t.data_ptr(), a.bytes.data(), a.bytes.size());
  } else if (ext == ".safetensors") {
    SafetensorsFile f(file);
    auto names = f.names();
    if (!f.contains(name) && names.size() != 1)
      fail("{}: holds {} tensors and none named '{}'", file.string(), names.size(), name);
    t = tensor_from_view(f.get(f.contains(name) ? name : names[0]));
  } else {
    fail("{}: not a .npy or .safetensors file", file.string());
  }
  if (!t.is_floating_point()) fail("{}: holds {} values; want floats", file.string(), c10::toString(t.scalar_type()));
  t = t.to(torch::kFloat32);
  if (!torch::isfinite(t).all().item<bool>()) fail("{}: contains NaN or infinity", file.string());
  return t;
}

std::map<std::string, torch::Tensor> state_dict(const torch::nn::Module& m) {
  std::map<std::string, torch::Tensor> out;
  for (auto& p : m.named_parameters(true)) out[p.key()] = p.value();
  for (auto& b : m.named_buffers(true)) out[b.key()] = b.value();
  return out;
}

void save_tensors(const std::map<std::string, torch::Tensor>& tensors, const fs::path& path,
                  const std::map<std::string, std::string>& metadata) {
  SafetensorsWriter w;
  for (auto& [name, t0] : tensors) {
    torch::Tensor t = t0.detach().to(torch::kCPU).contiguous();
    w.add(name, from_torch(t.scalar_type()), t.sizes().vec(), t.data_ptr(), t.numel() * t.element_size());
  }
  for (auto& [k, v] : metadata) w.set_metadata(k, v);
  w.write(path);
}

void save_module(const torch::nn::Module& m, const fs::path& path, const std::map<std::string, std::string>& metadata,
                 bool half) {
  auto sd = state_dict(m);
  if (half)
    for (auto& [k, t] : sd)
      if (t.is_floating_point()) t = t.to(torch::kFloat16);
  save_tensors(sd, path, metadata);
}

void load_module(torch::nn::Module& m, const fs::path& path, bool allow_extra) {
  SafetensorsFile f(path);
  auto sd = state_dict(m);
  torch::NoGradGuard ng;
  for (auto& [name, t] : sd) {
    if (!f.contains(name)) fail("{}: missing tensor '{}' (wrong model or config?)", path.string(), name);
    const TensorView& v = f.get(name);
    if (std::vector<int64_t>(v.shape.begin(), v.shape.end()) != t.sizes().vec())
      fail("{}: tensor '{}' has shape {}, the model expects {} (config mismatch?)", path.string(), name,
           shape_str(v.shape), shape_str(t.sizes().vec()));
    torch::Tensor src = tensor_from_view(v);
    if (src.is_floating_point() != t.is_floating_point())
      fail("{}: tensor '{}' is {}, the model expects {}", path.string(), name, safetensors_name(v.dtype), c10::toString(t.scalar_type()));
    if (src.is_floating_point() && !torch::isfinite(src).all().item<bool>())
      fail("{}: tensor '{}' contains NaN or infinity", path.string(), name);
    t.copy_(src.to(t.scalar_type()));
  }
  if (!allow_extra)
    for (auto& name : f.names())
      if (!sd.count(name)) fail("{}: unexpected tensor '{}' (wrong model or config?)", path.string(), name);
}

}  // namespace gaia
