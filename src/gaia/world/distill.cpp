#include "gaia/world/distill.h"

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"

namespace gaia::world {

torch::Tensor image_token_kl(const torch::Tensor& student, const torch::Tensor& teacher, const torch::Tensor& keep) {
  if (student.sizes() != teacher.sizes() || student.dim() != 4)
    fail("distillation: student logits {} and teacher logits {} must both be [B, T, n, K]",
         shape_str(student.sizes().vec()), shape_str(teacher.sizes().vec()));
  if (keep.dim() != 1 || keep.size(0) != student.size(0))
    fail("distillation: keep mask {} must be [B] for B = {}", shape_str(keep.sizes().vec()), student.size(0));
  auto idx = keep.to(torch::kCPU).to(torch::kBool).nonzero().view({-1}).to(student.device());
  if (idx.numel() == 0) return student.sum() * 0;
  const int64_t K = student.size(-1);
  auto s = torch::log_softmax(student.index_select(0, idx).reshape({-1, K}).to(torch::kFloat32), -1);
  auto t = torch::log_softmax(teacher.index_select(0, idx).reshape({-1, K}).to(torch::kFloat32), -1).detach();
  return (t.exp() * (t - s)).sum(-1).mean();
}

}  // namespace gaia::world
