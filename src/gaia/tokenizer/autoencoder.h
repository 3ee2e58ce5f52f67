#pragma once
// The image tokenizer of §2.2: a fully convolutional encoder E, the vector quantiser, and a decoder that is used only
// to train the tokenizer (and for quick previews). x [B, 3, H, W] in [-1, 1] -> tokens [B, H/D, W/D] in [0, K).
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/torch/conv_blocks.h"
#include "gaia/tokenizer/quantizer.h"

namespace gaia::tokenizer {

// [B, 3, H, W] -> [B, z_channels, H/D, W/D]
struct EncoderImpl : torch::nn::Module {
  explicit EncoderImpl(const TokenizerConfig& c);
  torch::Tensor forward(torch::Tensor x);
  torch::nn::Conv2d conv_in{nullptr}, conv_out{nullptr};
  torch::nn::Sequential body;
  torch::nn::GroupNorm norm_out{nullptr};
};
TORCH_MODULE(Encoder);

// [B, z_channels, H/D, W/D] -> [B, 3, H, W]
struct DecoderImpl : torch::nn::Module {
  explicit DecoderImpl(const TokenizerConfig& c);
  torch::Tensor forward(torch::Tensor z);
  torch::nn::Conv2d conv_in{nullptr}, conv_out{nullptr};
  torch::nn::Sequential body;
  torch::nn::Sequential token{nullptr};   // config token_blocks ResBlocks at the token grid, absent when 0
  torch::nn::Sequential refine{nullptr};  // config refine_blocks full-resolution ResBlocks, absent when 0
  torch::nn::GroupNorm norm_out{nullptr};
};
TORCH_MODULE(Decoder);

struct TokenizerOutput {
  torch::Tensor reconstruction;  // [B, 3, H, W]
  QuantizerOutput q;
};

struct ImageTokenizerImpl : torch::nn::Module {
  // dino_dim > 0 adds the linear head that maps codes to DINO feature space (the §2.2 inductive-bias loss).
  explicit ImageTokenizerImpl(const Config& c, int64_t dino_dim = 0);
  TokenizerOutput forward(const torch::Tensor& x);
  QuantizerOutput encode(const torch::Tensor& x);
  torch::Tensor tokenize(const torch::Tensor& x) { return encode(x).indices; }  // [B, h, w]
  torch::Tensor decode_tokens(const torch::Tensor& indices);                    // [B, h, w] -> [B, 3, H, W]
  int64_t parameter_count(bool with_heads = false) const;

  TokenizerConfig cfg;
  int height, width;
  Encoder encoder{nullptr};
  VectorQuantizer quantizer{nullptr};
  Decoder decoder{nullptr};
  torch::nn::Linear dino_head{nullptr};
};
TORCH_MODULE(ImageTokenizer);

// Images <-> tensors: BGR uint8 HxWx3 <-> RGB float [3, H, W] in [-1, 1].
torch::Tensor image_to_tensor(const void* bgr_data, int height, int width);
void tensor_to_image(const torch::Tensor& chw, void* bgr_out);  // clamps to [-1, 1]

}  // namespace gaia::tokenizer
