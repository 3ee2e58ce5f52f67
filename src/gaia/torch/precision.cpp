#include "gaia/torch/precision.h"

#include <cstdlib>

#include <ATen/autocast_mode.h>
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <cpuid.h>
#endif

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

namespace {

// The instructions themselves, from CPUID: leaf 7 sub-leaf 1 EAX bit 5 (AVX512_BF16), leaf 7 EDX bit 22 (AMX-BF16).
bool cpuid_bf16() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  unsigned a, b, c, d;
  if (__get_cpuid_max(0, nullptr) < 7) return false;
  __cpuid_count(7, 0, a, b, c, d);
  const bool amx = d & (1u << 22);
  __cpuid_count(7, 1, a, b, c, d);
  return amx || (a & (1u << 5));
#else
  return false;  // other CPUs (ARM's BF16 extension among them) are not detected: fp32 is the safe choice
#endif
}

// A cap set in the environment that keeps LibTorch's kernels below bf16's instructions.
bool capped_below_bf16() {
  if (const char* aten = std::getenv("ATEN_CPU_CAPABILITY")) {
    const std::string v = aten;
    if (v == "default" || v == "avx2" || v == "avx") return true;
  }
  for (const char* name : {"ONEDNN_MAX_CPU_ISA", "DNNL_MAX_CPU_ISA"}) {
    const char* isa = std::getenv(name);
    if (!isa) continue;
    const std::string v = isa;
    if (v.find("BF16") == std::string::npos && v.find("AMX") == std::string::npos && v != "ALL") return true;
  }
  return false;
}

}  // namespace

bool cpu_has_bf16() {
  static const bool has = cpuid_bf16() && !capped_below_bf16();
  return has;
}

Precision precision_for(const std::string& s, const torch::Device& device,
                        const std::function<void(const std::string&)>& note) {
  const Precision p = parse_precision(s);
  if (p == Precision::kFp16 && !device.is_cuda())
    fail("--precision fp16 needs a CUDA device (LibTorch's CPU autocast does bf16 only): use bf16 on the CPU");
  if (p == Precision::kBf16 && device.is_cpu() && !cpu_has_bf16()) {
    if (note)
      note("--precision bf16: this CPU has no bf16 instructions (AVX512_BF16 or AMX), where LibTorch emulates bf16 "
           "many times slower than fp32 (docs/benchmarks.md): running in fp32 instead");
    return Precision::kFp32;
  }
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
