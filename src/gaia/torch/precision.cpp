#include "gaia/torch/precision.h"

#include <ATen/autocast_mode.h>

#include "gaia/core/error.h"

namespace gaia {

Precision parse_precision(const std::string& s) {
  if (s == "fp32") return Precision::kFp32;
  if (s == "bf16") return Precision::kBf16;
  if (s == "fp16") return Precision::kFp16;
  fail("precision '{}': expected fp32, bf16 or fp16", s);
}

std::string to_string(Precision p) {
  switch (p) {
    case Precision::kFp32: return "fp32";
    case Precision::kBf16: return "bf16";
    case Precision::kFp16: return "fp16";
  }
  return "?";
}

Precision precision_for(const std::string& s, const torch::Device& device) {
  const Precision p = parse_precision(s);
  if (p == Precision::kFp16 && !device.is_cuda())
    fail("--precision fp16 needs a CUDA device (LibTorch's CPU autocast does bf16 only): use bf16 on the CPU");
  return p;
}

Autocast::Autocast(Precision p, const torch::Device& device) : cuda_(device.is_cuda()) {
  was_enabled_ = cuda_ ? at::autocast::is_enabled() : at::autocast::is_cpu_enabled();
  was_dtype_ = cuda_ ? at::autocast::get_autocast_gpu_dtype() : at::autocast::get_autocast_cpu_dtype();
  const bool on = p != Precision::kFp32;
  const auto dtype = p == Precision::kFp16 ? at::kHalf : at::kBFloat16;
  if (cuda_) {
    at::autocast::set_enabled(on);
    if (on) at::autocast::set_autocast_gpu_dtype(dtype);
  } else {
    at::autocast::set_cpu_enabled(on);
    if (on) at::autocast::set_autocast_cpu_dtype(dtype);
  }
  at::autocast::increment_nesting();
}

Autocast::~Autocast() {
  // The cast weights are cached for the outermost region only; leaving it frees them.
  if (at::autocast::decrement_nesting() == 0) at::autocast::clear_cache();
  if (cuda_) {
    at::autocast::set_enabled(was_enabled_);
    at::autocast::set_autocast_gpu_dtype(was_dtype_);
  } else {
    at::autocast::set_cpu_enabled(was_enabled_);
    at::autocast::set_autocast_cpu_dtype(was_dtype_);
  }
}

LossScaler::LossScaler(Precision p, double initial, int growth_interval)
    : active_(p == Precision::kFp16), scale_(active_ ? initial : 1.0), growth_interval_(growth_interval) {}

bool LossScaler::update(bool finite) {
  if (!active_) return finite;
  if (!finite) {
    scale_ = std::max(1.0, scale_ / 2);
    good_steps_ = 0;
    return false;
  }
  if (++good_steps_ >= growth_interval_) {
    scale_ = std::min(scale_ * 2, 16777216.0);
    good_steps_ = 0;
  }
  return true;
}

}  // namespace gaia
