#include "gaia/decoder/unet.h"

#include <cmath>

#include "gaia/core/error.h"
#include "gaia/torch/attention.h"

namespace gaia::decoder {

namespace F = torch::nn::functional;

namespace {
// A norm (group or layer) of float32 input: under bf16's autocast (--precision bf16) activations may arrive in
// bf16, and LibTorch's CPU norms take no bf16 input with float32 weights. A no-op cast in float32.
template <class Norm>
torch::Tensor normed(Norm& norm, const torch::Tensor& x) { return norm(x.to(torch::kFloat)); }
}  // namespace

torch::Tensor timestep_embedding(const torch::Tensor& t, int64_t dim) {
  // Transformer-style sinusoids of 1000 t (DDPM convention), half sine and half cosine.
  const int64_t half = dim / 2;
  auto freqs = torch::exp(-std::log(10000.0) * torch::arange(half, t.options().dtype(torch::kFloat32)) / half);
  auto args = (t.to(torch::kFloat32) * 1000.0).unsqueeze(1) * freqs.unsqueeze(0);  // [N, half]
  auto e = torch::cat({torch::sin(args), torch::cos(args)}, 1);
  if (dim % 2) e = F::pad(e, F::PadFuncOptions({0, 1}));
  return e;
}

TimeResBlockImpl::TimeResBlockImpl(int64_t cin, int64_t cout, int64_t emb_dim) {
  norm1 = register_module("norm1", group_norm(cin));
  conv1 = register_module("conv1", torch::nn::Conv2d(torch::nn::Conv2dOptions(cin, cout, 3).padding(1)));
  film = register_module("film", torch::nn::Linear(emb_dim, 2 * cout));
  norm2 = register_module("norm2", group_norm(cout));
  conv2 = register_module("conv2", torch::nn::Conv2d(torch::nn::Conv2dOptions(cout, cout, 3).padding(1)));
  if (cin != cout) skip = register_module("skip", torch::nn::Conv2d(torch::nn::Conv2dOptions(cin, cout, 1)));
  // Zero-initialised last conv: every block starts as its skip path, which keeps a deep U-Net stable early on.
  torch::NoGradGuard ng;
  conv2->weight.zero_();
  conv2->bias.zero_();
}

torch::Tensor TimeResBlockImpl::forward(const torch::Tensor& x, const torch::Tensor& emb) {
  auto h = conv1(F::silu(normed(norm1, x)));                             // [N, cout, H, W]
  auto ss = film(F::silu(emb)).unsqueeze(-1).unsqueeze(-1).chunk(2, 1);  // 2 x [N, cout, 1, 1]
  h = normed(norm2, h) * (1 + ss[0]) + ss[1];
  h = conv2(F::silu(h));
  return (skip ? skip(x) : x) + h;
}

SpatialAttentionImpl::SpatialAttentionImpl(int64_t c, int64_t heads_) : heads(heads_) {
  if (c % heads) fail("decoder: {} channels do not split into {} attention heads", c, heads);
  norm = register_module("norm", group_norm(c));
  qkv = register_module("qkv", torch::nn::Linear(c, 3 * c));
  proj = register_module("proj", torch::nn::Linear(c, c));
}

namespace {
// q, k, v [N, heads, L, hd] -> [N, L, heads * hd]; `bias` broadcastable to [N, heads, L, L] or undefined.
torch::Tensor attend(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v, const torch::Tensor& bias) {
  return attention(q, k, v, bias).transpose(1, 2).flatten(2);  // [N, heads, L, hd] -> [N, L, heads * hd]
}
}  // namespace

torch::Tensor SpatialAttentionImpl::forward(const torch::Tensor& x) {
  const int64_t N = x.size(0), C = x.size(1), H = x.size(2), W = x.size(3), hd = C / heads;
  auto h = normed(norm, x).flatten(2).transpose(1, 2);                  // [N, HW, C]
  auto q = qkv(h).view({N, H * W, 3, heads, hd}).permute({2, 0, 3, 1, 4});  // [3, N, heads, HW, hd]
  auto o = proj(attend(q[0], q[1], q[2], {}));                          // [N, HW, C]
  return x + o.transpose(1, 2).reshape({N, C, H, W});
}

TemporalAttentionImpl::TemporalAttentionImpl(int64_t c, int64_t heads_, int64_t max_offset_)
    : heads(heads_), max_offset(max_offset_) {
  if (c % heads) fail("decoder: {} channels do not split into {} attention heads", c, heads);
  norm = register_module("norm", torch::nn::LayerNorm(torch::nn::LayerNormOptions({c})));
  qkv = register_module("qkv", torch::nn::Linear(c, 3 * c));
  proj = register_module("proj", torch::nn::Linear(c, c));
  rel_bias = register_parameter("rel_bias", torch::zeros({heads, 2 * max_offset + 1}));
  torch::NoGradGuard ng;
  proj->weight.zero_();
  proj->bias.zero_();
}

torch::Tensor TemporalAttentionImpl::forward(const torch::Tensor& x, int64_t T) {
  const int64_t BT = x.size(0), C = x.size(1), H = x.size(2), W = x.size(3), B = BT / T, hd = C / heads;
  // [B*T, C, H, W] -> [B*H*W, T, C]: every position of the frame is a sequence over time.
  auto h = x.view({B, T, C, H * W}).permute({0, 3, 1, 2}).reshape({B * H * W, T, C});
  auto q = qkv(normed(norm, h)).view({B * H * W, T, 3, heads, hd}).permute({2, 0, 3, 1, 4});  // [3, BHW, heads, T, hd]
  auto pos = torch::arange(T, x.options().dtype(torch::kLong));
  auto rel = (pos.unsqueeze(0) - pos.unsqueeze(1)).clamp(-max_offset, max_offset) + max_offset;  // [T, T]: j - i
  auto bias = rel_bias.index_select(1, rel.flatten()).view({1, heads, T, T});
  auto o = proj(attend(q[0], q[1], q[2], bias));  // [BHW, T, C]
  return x + o.view({B, H * W, T, C}).permute({0, 2, 3, 1}).reshape({BT, C, H, W});
}

UNetLayerImpl::UNetLayerImpl(int64_t cin, int64_t cout, int64_t emb_dim, bool with_spatial, int64_t heads) {
  res = register_module("res", TimeResBlock(cin, cout, emb_dim));
  if (with_spatial) spatial = register_module("spatial", SpatialAttention(cout, heads));
}

torch::Tensor UNetLayerImpl::forward(torch::Tensor x, const torch::Tensor& emb, int64_t T, bool use_temporal) {
  x = res(x, emb);
  if (spatial) x = spatial(x);
  if (use_temporal && temporal) x = temporal(x, T);
  return x;
}

VideoUNetImpl::VideoUNetImpl(const DecoderConfig& c, int64_t K_, int64_t D_) : cfg(c), K(K_), D(D_) {
  const int L = int(c.channel_mult.size());
  const int64_t ch = c.channels, emb = 4 * ch, E = c.token_embed_dim;
  const int64_t max_offset = c.frames - 1;  // relative offsets within one window of T' frames
  auto has_attn = [&](int level) { return std::find(c.attn_levels.begin(), c.attn_levels.end(), level) != c.attn_levels.end(); };
  auto has_temporal = [&](int level) {
    return std::find(c.temporal_levels.begin(), c.temporal_levels.end(), level) != c.temporal_levels.end();
  };
  auto layer = [&](int64_t cin, int64_t cout, int level) {
    UNetLayer l(cin, cout, emb, has_attn(level), c.heads);
    if (has_temporal(level)) l->temporal = l->register_module("temporal", TemporalAttention(cout, c.heads, max_offset));
    return l;
  };
  token_embedding = register_module("token_embedding", torch::nn::Embedding(K + 1, E));
  rate_embedding = register_module("rate_embedding", torch::nn::Embedding(3, emb));
  time_fc1 = register_module("time_fc1", torch::nn::Linear(ch, emb));
  time_fc2 = register_module("time_fc2", torch::nn::Linear(emb, emb));
  const int64_t cin = 3 + 1 + E + (c.cond_image ? 3 : 0);  // noisy frame, context mask, tokens, decoded tokens
  int64_t w = ch * c.channel_mult[0];
  conv_in = register_module("conv_in", torch::nn::Conv2d(torch::nn::Conv2dOptions(cin, w, 3).padding(1)));
  down = register_module("down", torch::nn::ModuleList());
  up = register_module("up", torch::nn::ModuleList());
  token_proj = register_module("token_proj", torch::nn::ModuleList());
  downsamplers = register_module("downsamplers", torch::nn::ModuleList());
  upsamplers = register_module("upsamplers", torch::nn::ModuleList());
  std::vector<int64_t> skips{w};
  for (int i = 0; i < L; ++i) {
    const int64_t wo = ch * c.channel_mult[size_t(i)];
    // The token embedding is also added at the start of every level (1x1 conv to the level's width).
    token_proj->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(E, w, 1)));
    for (int r = 0; r < c.res_blocks; ++r) {
      down->push_back(layer(w, wo, i));
      down_level.push_back(i);
      w = wo;
      skips.push_back(w);
    }
    if (i + 1 < L) {
      downsamplers->push_back(Downsample(w));
      skips.push_back(w);
    }
  }
  mid1 = register_module("mid1", layer(w, w, L - 1));
  mid2 = register_module("mid2", layer(w, w, L - 1));
  for (int i = L - 1; i >= 0; --i) {
    const int64_t wo = ch * c.channel_mult[size_t(i)];
    for (int r = 0; r < c.res_blocks + 1; ++r) {
      const int64_t s = skips.back();
      skips.pop_back();
      up->push_back(layer(w + s, wo, i));
      up_level.push_back(i);
      w = wo;
    }
    if (i > 0) upsamplers->push_back(Upsample(w));
  }
  norm_out = register_module("norm_out", group_norm(w));
  conv_out = register_module("conv_out", torch::nn::Conv2d(torch::nn::Conv2dOptions(w, 3, 3).padding(1)));
  torch::NoGradGuard ng;
  conv_out->weight.zero_();
  conv_out->bias.zero_();
}

int64_t VideoUNetImpl::parameter_count() const {
  int64_t n = 0;
  for (const auto& p : parameters()) n += p.numel();
  return n;
}

torch::Tensor VideoUNetImpl::forward(const DenoiserInput& in) {
  const int64_t B = in.x.size(0), T = in.x.size(1), H = in.x.size(3), W = in.x.size(4);
  const int64_t h = in.tokens.size(2), w = in.tokens.size(3);
  if (h * D != H || w * D != W)
    fail("decoder: token grid {}x{} does not match frames {}x{} at downsampling {}", h, w, H, W, D);
  const int64_t N = B * T;
  // Conditioning embedding per frame: diffusion time + frame rate.       emb [N, 4ch]
  auto emb = time_fc2(F::silu(time_fc1(timestep_embedding(in.time.reshape({N}), cfg.channels))));
  emb = emb + rate_embedding(in.rate).unsqueeze(1).expand({B, T, emb.size(1)}).reshape({N, emb.size(1)});
  // Tokens on their grid -> [N, E, h, w] -> nearest-upsampled to pixels.
  auto tok = token_embedding(in.tokens.reshape({N, h, w})).permute({0, 3, 1, 2});
  auto tok_px = F::interpolate(tok, F::InterpolateFuncOptions().size(std::vector<int64_t>{H, W}).mode(torch::kNearest));
  std::vector<torch::Tensor> parts{in.x.reshape({N, 3, H, W}),
                                   in.context.reshape({N, 1, 1, 1}).expand({N, 1, H, W}).to(in.x.dtype()), tok_px};
  if (cfg.cond_image) parts.push_back(in.cond_image.reshape({N, 3, H, W}));
  auto x = conv_in(torch::cat(parts, 1));  // [N, ch, H, W]

  std::vector<torch::Tensor> skips{x};
  size_t li = 0;
  const int L = int(cfg.channel_mult.size());
  for (int i = 0; i < L; ++i) {
    auto t_l = F::interpolate(tok, F::InterpolateFuncOptions().size(std::vector<int64_t>{x.size(2), x.size(3)}).mode(torch::kNearest));
    x = x + token_proj[size_t(i)]->as<torch::nn::Conv2d>()->forward(t_l);
    for (int r = 0; r < cfg.res_blocks; ++r) {
      x = down[li++]->as<UNetLayer>()->forward(x, emb, T, in.temporal);
      skips.push_back(x);
    }
    if (i + 1 < L) {
      x = downsamplers[size_t(i)]->as<Downsample>()->forward(x);
      skips.push_back(x);
    }
  }
  x = mid1(x, emb, T, in.temporal);
  x = mid2(x, emb, T, in.temporal);
  li = 0;
  size_t ui = 0;
  for (int i = L - 1; i >= 0; --i) {
    for (int r = 0; r < cfg.res_blocks + 1; ++r) {
      auto s = skips.back();
      skips.pop_back();
      x = up[li++]->as<UNetLayer>()->forward(torch::cat({x, s}, 1), emb, T, in.temporal);
    }
    if (i > 0) x = upsamplers[ui++]->as<Upsample>()->forward(x);
  }
  x = conv_out(F::silu(normed(norm_out, x)));  // [N, 3, H, W]
  return x.view({B, T, 3, H, W});
}

}  // namespace gaia::decoder
