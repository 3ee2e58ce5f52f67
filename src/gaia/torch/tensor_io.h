#pragma once
// LibTorch <-> gaia formats: devices, safetensors state dicts of modules, tensors from mapped files.
#include <map>
#include <string>

#include <torch/torch.h>

#include "gaia/core/safetensors.h"

namespace gaia {

// "cpu", "cuda", "cuda:1"; a CUDA device on a build or machine without CUDA is an error that says so.
torch::Device parse_device(const std::string& s);

torch::Dtype to_torch(DType t);
DType from_torch(torch::Dtype t);

// Sets LibTorch's intra-op threads (0 = all cores); some builds otherwise default to one thread.
void set_torch_threads(int n);

// Keeps freed blocks in the process instead of returning them to the OS: glibc serves allocations above 32 MB with
// fresh mmap()s and trims the heap's free top, so every training step would pay page faults and page clearing for
// its attention scores. A process's resident memory stays at its peak. Called once by the app and the benches.
void configure_allocator();

// Copies a tensor out of a (mapped) safetensors view.
torch::Tensor tensor_from_view(const TensorView& v);

// The float array of a .npy file, or of a .safetensors file's tensor `name` (or its only tensor when `name` is
// not in it), as float32 on the CPU. Errors name the file: not found, not a float array, NaN or infinity.
torch::Tensor read_float_array(const fs::path& file, const std::string& name);

// All parameters and buffers of a module by their dotted names ("encoder.conv_in.weight").
std::map<std::string, torch::Tensor> state_dict(const torch::nn::Module& m);

// Writes a module's state dict as safetensors (atomically); `half` stores float tensors as F16.
void save_module(const torch::nn::Module& m, const fs::path& path, const std::map<std::string, std::string>& metadata = {},
                 bool half = false);

// Loads a state dict into a module. Every tensor of the module must be present with the same shape (errors name
// the file and tensor); extra tensors in the file are errors unless `allow_extra`. Float dtypes convert.
void load_module(torch::nn::Module& m, const fs::path& path, bool allow_extra = false);

// Writes named tensors (any dtype) as safetensors atomically.
void save_tensors(const std::map<std::string, torch::Tensor>& tensors, const fs::path& path,
                  const std::map<std::string, std::string>& metadata = {});

}  // namespace gaia
