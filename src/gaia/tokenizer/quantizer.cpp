#include "gaia/tokenizer/quantizer.h"

#include "gaia/torch/precision.h"

namespace gaia::tokenizer {

namespace F = torch::nn::functional;

VectorQuantizerImpl::VectorQuantizerImpl(int64_t z_channels, int64_t cd, int64_t k) : K(k), code_dim(cd) {
  proj_in = register_module("proj_in", torch::nn::Linear(z_channels, cd));
  codebook = register_module("codebook", torch::nn::Embedding(k, cd));
  proj_out = register_module("proj_out", torch::nn::Linear(cd, z_channels));
  torch::NoGradGuard ng;
  codebook->weight.normal_();
}

torch::Tensor VectorQuantizerImpl::normalized_codebook() const {
  return F::normalize(codebook->weight, F::NormalizeFuncOptions().dim(1));
}

QuantizerOutput VectorQuantizerImpl::forward(const torch::Tensor& z_in) {
  // The nearest code in float32 under any autocast: in bf16, near-equal cosines pick the wrong code.
  Autocast fp32(Precision::kFp32, z_in.device());
  const auto z = z_in.to(torch::kFloat);
  const auto B = z.size(0), h = z.size(2), w = z.size(3);
  auto ze = proj_in(z.permute({0, 2, 3, 1}).reshape({-1, z.size(1)}));   // [N, code_dim]
  ze = F::normalize(ze, F::NormalizeFuncOptions().dim(1));
  auto cb = normalized_codebook();                                          // [K, code_dim]
  auto idx = torch::matmul(ze.detach(), cb.detach().t()).argmax(1);        // max cosine = min L2 on the sphere
  auto e = cb.index_select(0, idx);                                         // [N, code_dim]
  QuantizerOutput out;
  out.codebook_loss = (ze.detach() - e).pow(2).sum(1).mean();
  out.commit_loss = (ze - e.detach()).pow(2).sum(1).mean();
  auto st = ze + (e - ze).detach();                                         // straight-through estimator
  out.codes = st.reshape({B, h, w, code_dim}).permute({0, 3, 1, 2});
  out.z_q = proj_out(st).reshape({B, h, w, -1}).permute({0, 3, 1, 2});
  out.indices = idx.reshape({B, h, w});
  return out;
}

torch::Tensor VectorQuantizerImpl::lookup(const torch::Tensor& indices) {
  auto e = normalized_codebook().index_select(0, indices.reshape({-1}));
  auto B = indices.size(0), h = indices.size(1), w = indices.size(2);
  return proj_out(e).reshape({B, h, w, -1}).permute({0, 3, 1, 2});
}

int64_t VectorQuantizerImpl::restart_dead_codes(const torch::Tensor& usage, const torch::Tensor& z_e, torch::Generator gen) {
  torch::NoGradGuard ng;
  auto dead = (usage == 0).nonzero().reshape({-1});
  const int64_t n = dead.size(0);
  if (n == 0 || z_e.size(0) == 0) return 0;
  auto pick = torch::randint(z_e.size(0), {n}, gen, torch::TensorOptions().dtype(torch::kLong).device(z_e.device()));
  auto noise = torch::randn({n, code_dim}, gen, z_e.options()) * 0.01;
  const auto dev = codebook->weight.device();  // the encoder outputs and draws may be on the CPU
  codebook->weight.index_copy_(0, dead.to(dev), (z_e.index_select(0, pick) + noise).to(dev, codebook->weight.scalar_type()));
  return n;
}

}  // namespace gaia::tokenizer
