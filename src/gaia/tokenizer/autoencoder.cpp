#include "gaia/tokenizer/autoencoder.h"

#include "gaia/core/error.h"

namespace gaia::tokenizer {

namespace F = torch::nn::functional;

EncoderImpl::EncoderImpl(const TokenizerConfig& t) {
  const int L = static_cast<int>(t.channel_mult.size());
  int64_t c = int64_t(t.channels) * t.channel_mult[0];
  conv_in = register_module("conv_in", torch::nn::Conv2d(torch::nn::Conv2dOptions(3, c, 3).padding(1)));
  for (int i = 0; i < L; ++i) {
    int64_t co = int64_t(t.channels) * t.channel_mult[static_cast<size_t>(i)];
    for (int r = 0; r < t.res_blocks; ++r) { body->push_back(ResBlock(c, co)); c = co; }
    if (i + 1 < L) body->push_back(Downsample(c));
  }
  body->push_back(ResBlock(c, c));
  body->push_back(ResBlock(c, c));
  register_module("body", body);
  norm_out = register_module("norm_out", group_norm(c));
  conv_out = register_module("conv_out", torch::nn::Conv2d(torch::nn::Conv2dOptions(c, t.z_channels, 3).padding(1)));
}

torch::Tensor EncoderImpl::forward(torch::Tensor x) {
  return conv_out(F::silu(norm_out(body->forward(conv_in(x)))));
}

namespace {
// n ResBlocks(c, c) whose last convolution starts at zero: each is the identity until it is trained, so a trained
// decoder grown by them decodes exactly as before.
torch::nn::Sequential identity_blocks(int n, int64_t c) {
  torch::nn::Sequential s;
  for (int r = 0; r < n; ++r) {
    ResBlock b(c, c);
    torch::NoGradGuard ng;
    b->conv2->weight.zero_();
    b->conv2->bias.zero_();
    s->push_back(b);
  }
  return s;
}
}  // namespace

DecoderImpl::DecoderImpl(const TokenizerConfig& t) {
  const int L = static_cast<int>(t.channel_mult.size());
  int64_t c = int64_t(t.channels) * t.channel_mult.back();
  conv_in = register_module("conv_in", torch::nn::Conv2d(torch::nn::Conv2dOptions(t.z_channels, c, 3).padding(1)));
  if (t.token_blocks > 0) token = register_module("token", identity_blocks(t.token_blocks, c));
  body->push_back(ResBlock(c, c));
  body->push_back(ResBlock(c, c));
  for (int i = L - 1; i >= 0; --i) {
    int64_t co = int64_t(t.channels) * t.channel_mult[static_cast<size_t>(i)];
    for (int r = 0; r < t.res_blocks + 1; ++r) { body->push_back(ResBlock(c, co)); c = co; }
    if (i > 0) body->push_back(Upsample(c));
  }
  register_module("body", body);
  if (t.refine_blocks > 0) refine = register_module("refine", identity_blocks(t.refine_blocks, c));
  norm_out = register_module("norm_out", group_norm(c));
  conv_out = register_module("conv_out", torch::nn::Conv2d(torch::nn::Conv2dOptions(c, 3, 3).padding(1)));
}

torch::Tensor DecoderImpl::forward(torch::Tensor z) {
  auto h = conv_in(z);                // [B, channels * channel_mult.back(), H/D, W/D]
  if (token) h = token->forward(h);
  h = body->forward(h);               // [B, channels * channel_mult[0], H, W]
  if (refine) h = refine->forward(h);
  return conv_out(F::silu(norm_out(h)));
}

ImageTokenizerImpl::ImageTokenizerImpl(const Config& c, int64_t dino_dim)
    : cfg(c.tokenizer), height(c.data.height), width(c.data.width) {
  encoder = register_module("encoder", Encoder(cfg));
  quantizer = register_module("quantizer", VectorQuantizer(cfg.z_channels, cfg.code_dim, cfg.codebook_size));
  decoder = register_module("decoder", Decoder(cfg));
  if (dino_dim > 0) dino_head = register_module("dino_head", torch::nn::Linear(cfg.code_dim, dino_dim));
}

QuantizerOutput ImageTokenizerImpl::encode(const torch::Tensor& x) {
  if (x.dim() != 4 || x.size(1) != 3 || x.size(2) != height || x.size(3) != width)
    fail("tokenizer: expected images [B, 3, {}, {}], got {}", height, width, c10::str(x.sizes()));
  return quantizer->forward(encoder->forward(x));
}

TokenizerOutput ImageTokenizerImpl::forward(const torch::Tensor& x) {
  TokenizerOutput o;
  o.q = encode(x);
  o.reconstruction = decoder->forward(o.q.z_q);
  return o;
}

torch::Tensor ImageTokenizerImpl::decode_tokens(const torch::Tensor& indices) {
  return decoder->forward(quantizer->lookup(indices));
}

int64_t ImageTokenizerImpl::parameter_count(bool with_heads) const {
  int64_t n = 0;
  for (auto& p : named_parameters(true))
    if (with_heads || p.key().rfind("dino_head", 0) != 0) n += p.value().numel();
  return n;
}

torch::Tensor image_to_tensor(const void* bgr, int h, int w) {
  auto t = torch::from_blob(const_cast<void*>(bgr), {h, w, 3}, torch::kUInt8);
  return t.flip({2}).permute({2, 0, 1}).to(torch::kFloat32).div(127.5).sub(1.0).contiguous();
}

void tensor_to_image(const torch::Tensor& chw, void* bgr_out) {
  auto t = chw.detach().to(torch::kCPU).clamp(-1, 1).add(1).mul(127.5).round().to(torch::kUInt8);
  t = t.permute({1, 2, 0}).flip({2}).contiguous();
  std::memcpy(bgr_out, t.data_ptr(), static_cast<size_t>(t.numel()));
}

}  // namespace gaia::tokenizer
