#include "gaia/world/transformer.h"

#include <cmath>

#include <torch/version.h>

namespace gaia::world {

namespace F = torch::nn::functional;

CausalSelfAttentionImpl::CausalSelfAttentionImpl(int64_t d_, int64_t heads_) : heads(heads_), d(d_) {
  TORCH_CHECK(d % heads == 0, "d_model ", d, " is not divisible by n_heads ", heads);
  qkv = register_module("qkv", torch::nn::Linear(d, 3 * d));
  proj = register_module("proj", torch::nn::Linear(d, d));
}

namespace {

// q [B, H, Lq, hd], k/v [B, H, Lk, hd]; query i sits at key position offset + i and sees keys <= that.
torch::Tensor attend(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v, int64_t offset) {
  const int64_t Lq = q.size(2), Lk = k.size(2);
#if TORCH_VERSION_MAJOR >= 2
  if (offset == 0 && Lq == Lk) return at::scaled_dot_product_attention(q, k, v, {}, 0.0, /*is_causal=*/true);
#endif
  const int64_t B = q.size(0), H = q.size(1), hd = q.size(3);
  const double scale = 1.0 / std::sqrt(double(hd));
  auto q3 = q.reshape({B * H, Lq, hd}), kt = k.reshape({B * H, Lk, hd}).transpose(1, 2);
  torch::Tensor att;  // [B * H, Lq, Lk]
  if (Lq > 1) {
    // Additive causal mask fused into the product (one pass over the L x L scores instead of three).
    auto qi = torch::arange(offset, offset + Lq, q.options().dtype(torch::kLong)).unsqueeze(1);
    auto kj = torch::arange(Lk, q.options().dtype(torch::kLong)).unsqueeze(0);
    auto mask = torch::zeros({Lq, Lk}, q.options()).masked_fill_(kj > qi, -std::numeric_limits<float>::infinity());
    att = torch::baddbmm(mask, q3, kt, /*beta=*/1.0, /*alpha=*/scale);
  } else {
    att = torch::bmm(q3, kt) * scale;
  }
  return torch::bmm(torch::softmax(att, -1), v.reshape({B * H, Lk, hd})).view({B, H, Lq, hd});
}

}  // namespace

torch::Tensor CausalSelfAttentionImpl::forward(const torch::Tensor& x, KVCache* cache, int layer) {
  const int64_t B = x.size(0), L = x.size(1), hd = d / heads;
  auto qkv_ = qkv->forward(x).view({B, L, 3, heads, hd}).permute({2, 0, 3, 1, 4});  // [3, B, H, L, hd]
  auto q = qkv_[0], k = qkv_[1], v = qkv_[2];
  int64_t offset = 0;
  if (cache) {
    offset = cache->length;
    TORCH_CHECK(offset + L <= cache->capacity(), "KV cache overflow: ", offset, " + ", L, " > ", cache->capacity());
    auto& K = cache->k[static_cast<size_t>(layer)];
    auto& V = cache->v[static_cast<size_t>(layer)];
    K.narrow(2, offset, L).copy_(k);
    V.narrow(2, offset, L).copy_(v);
    k = K.narrow(2, 0, offset + L);
    v = V.narrow(2, 0, offset + L);
  }
  auto y = attend(q, k, v, offset);  // [B, H, L, hd]
  return proj->forward(y.transpose(1, 2).reshape({B, L, d}));
}

BlockImpl::BlockImpl(int64_t d, int64_t heads) {
  ln1 = register_module("ln1", torch::nn::LayerNorm(torch::nn::LayerNormOptions({d})));
  attn = register_module("attn", CausalSelfAttention(d, heads));
  ln2 = register_module("ln2", torch::nn::LayerNorm(torch::nn::LayerNormOptions({d})));
  fc = register_module("fc", torch::nn::Linear(d, 4 * d));
  fc_proj = register_module("fc_proj", torch::nn::Linear(4 * d, d));
}

torch::Tensor BlockImpl::forward(const torch::Tensor& x, KVCache* cache, int layer) {
  auto h = x + attn->forward(ln1->forward(x), cache, layer);
  return h + fc_proj->forward(F::gelu(fc->forward(ln2->forward(h))));
}

namespace {

// The block is not an input of the autograd node, so its parameter gradients are accumulated by the nested backward
// in backward(); only the gradient of x is returned (the "reentrant" checkpoint of PyTorch).
struct CheckpointFn : torch::autograd::Function<CheckpointFn> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::Tensor x, BlockImpl* block) {
    ctx->saved_data["block"] = reinterpret_cast<int64_t>(block);
    ctx->save_for_backward({x});
    torch::NoGradGuard ng;
    return block->forward(x);
  }
  static torch::autograd::tensor_list backward(torch::autograd::AutogradContext* ctx,
                                               torch::autograd::tensor_list grad) {
    auto* block = reinterpret_cast<BlockImpl*>(ctx->saved_data["block"].toInt());
    auto x = ctx->get_saved_variables()[0].detach().requires_grad_(true);
    {
      torch::AutoGradMode on(true);
      auto y = block->forward(x);
      y.backward(grad[0]);
    }
    return {x.grad(), torch::Tensor()};
  }
};

}  // namespace

torch::Tensor checkpointed(Block& block, const torch::Tensor& x) {
  if (!torch::GradMode::is_enabled() || !x.requires_grad()) return block->forward(x);
  return CheckpointFn::apply(x, block.get());
}

}  // namespace gaia::world
