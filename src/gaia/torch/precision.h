#pragma once
// Mixed precision (run.precision, --precision): fp32 everywhere, or matrix products and convolutions in bf16 / fp16
// through LibTorch's autocast, with float32 master weights and AdamW state, and float32 where the numbers need it
// (softmax statistics, norms, losses, the VQ distance). fp16 also needs a loss scale against underflowing gradients.
#include <functional>
#include <string>

#include <torch/torch.h>

namespace gaia {

enum class Precision { kFp32, kBf16, kFp16 };

Precision parse_precision(const std::string& s);  // "fp32" | "bf16" | "fp16"; anything else fails naming it
std::string to_string(Precision p);
// Whether this CPU does bf16 arithmetic in hardware (AVX512_BF16 or AMX-BF16) and LibTorch may use it: not capped
// below that by ATEN_CPU_CAPABILITY or ONEDNN_MAX_CPU_ISA / DNNL_MAX_CPU_ISA. Without it LibTorch emulates bf16
// products in scalar code, many times slower than float32.
bool cpu_has_bf16();

// The precision `s` on `device`: fails with one line where that device's autocast cannot do it (fp16 on the CPU).
// bf16 on a CPU without bf16 instructions (cpu_has_bf16) falls back to fp32, and `note` gets one line saying so.
Precision precision_for(const std::string& s, const torch::Device& device,
                        const std::function<void(const std::string&)>& note = {});

// Autocast on `device` at `p` for the life of the object (fp32: autocast off, e.g. inside a block that must stay
// float32 within a bf16 region); the previous state comes back after.
class Autocast {
 public:
  Autocast(Precision p, const torch::Device& device);
  ~Autocast();
  Autocast(const Autocast&) = delete;
  Autocast& operator=(const Autocast&) = delete;

 private:
  bool cuda_, was_enabled_;
  at::ScalarType was_dtype_;
};

// fp16's dynamic loss scale (Micikevicius et al. 2018): the loss is multiplied by scale() before backward; a step
// whose gradients overflow is skipped and halves the scale, and every `growth_interval` good steps double it.
// For bf16 and fp32 the scale stays 1.
class LossScaler {
 public:
  explicit LossScaler(Precision p, double initial = 65536.0, int growth_interval = 2000);
  double scale() const { return scale_; }
  // After a step: `finite` = its gradients were finite (the step was taken). Returns false for a skipped step.
  bool update(bool finite);
  bool active() const { return active_; }

 private:
  bool active_;
  double scale_;
  int growth_interval_, good_steps_ = 0;
};

}  // namespace gaia
