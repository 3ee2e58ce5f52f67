#pragma once
// The video diffusion decoder's network (§2.4): a 3D U-Net in the style of Ho et al. 2022. Convolutions and ResNet
// blocks work per frame (2D); attention is factorised into spatial attention within a frame (at low resolutions)
// and temporal attention across frames at each position, with a learned relative-position bias. Turning the
// temporal layers off (`temporal = false`) makes the same network denoise every frame as an independent image.
//
// Inputs per frame: the noisy frame (or the clean frame where it is context), the context mask channel, the image
// tokens as learned embeddings on the token grid (upsampled to pixels and also added at every level), optionally
// the tokenizer decoder's image of the tokens (`cond_image`), the diffusion time and the frame rate.
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/torch/conv_blocks.h"

namespace gaia::decoder {

// x [N, cin, H, W], emb [N, E] -> [N, cout, H, W]: GN, SiLU, conv, FiLM(emb) (scale, shift), GN, SiLU, conv; skip.
struct TimeResBlockImpl : torch::nn::Module {
  TimeResBlockImpl(int64_t cin, int64_t cout, int64_t emb_dim);
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& emb);
  torch::nn::GroupNorm norm1{nullptr}, norm2{nullptr};
  torch::nn::Conv2d conv1{nullptr}, conv2{nullptr}, skip{nullptr};
  torch::nn::Linear film{nullptr};
};
TORCH_MODULE(TimeResBlock);

// x [N, C, H, W] -> same: pre-norm multi-head self-attention over the H*W positions of each frame.
struct SpatialAttentionImpl : torch::nn::Module {
  SpatialAttentionImpl(int64_t channels, int64_t heads);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::GroupNorm norm{nullptr};
  torch::nn::Linear qkv{nullptr}, proj{nullptr};
  int64_t heads;
};
TORCH_MODULE(SpatialAttention);

// x [B*T, C, H, W] -> same: pre-norm self-attention across the T frames at each position; the logits get a learned
// bias per head and relative offset j - i (clamped to +-max_offset), so the layer knows order and distance in time.
// The output projection starts at zero: a new temporal layer is the identity, as with `temporal = false`.
struct TemporalAttentionImpl : torch::nn::Module {
  TemporalAttentionImpl(int64_t channels, int64_t heads, int64_t max_offset = 16);
  torch::Tensor forward(const torch::Tensor& x, int64_t T);
  torch::nn::LayerNorm norm{nullptr};
  torch::nn::Linear qkv{nullptr}, proj{nullptr};
  torch::Tensor rel_bias;  // [heads, 2 * max_offset + 1]
  int64_t heads, max_offset;
};
TORCH_MODULE(TemporalAttention);

struct DenoiserInput {
  torch::Tensor x;        // [B, T, 3, H, W] noisy frames; context frames clean
  torch::Tensor context;  // [B, T] float, 1 = clean context frame
  torch::Tensor tokens;   // [B, T, h, w] int64 in [0, K]; K = no token (masked by dropout, or a frame without tokens)
  torch::Tensor cond_image;  // [B, T, 3, H, W] tokenizer-decoder image of the tokens (zeros where none); if enabled
  torch::Tensor time;     // [B, T] diffusion time t' in [0, 1] per frame (0 for context frames)
  torch::Tensor rate;     // [B] int64 frame-rate index (tasks.h kRates)
  bool temporal = true;   // false: temporal attention skipped, frames are independent images
};

// One layer of the U-Net at one resolution: ResNet block, optional spatial attention, temporal attention.
struct UNetLayerImpl : torch::nn::Module {
  UNetLayerImpl(int64_t cin, int64_t cout, int64_t emb_dim, bool spatial, int64_t heads);
  torch::Tensor forward(torch::Tensor x, const torch::Tensor& emb, int64_t T, bool temporal);
  TimeResBlock res{nullptr};
  SpatialAttention spatial{nullptr};
  TemporalAttention temporal{nullptr};
};
TORCH_MODULE(UNetLayer);

struct VideoUNetImpl : torch::nn::Module {
  // K: tokenizer codebook size; D: tokenizer downsampling (token grid -> pixels).
  VideoUNetImpl(const DecoderConfig& c, int64_t K, int64_t D);
  torch::Tensor forward(const DenoiserInput& in);  // -> v prediction [B, T, 3, H, W]
  int64_t parameter_count() const;

  DecoderConfig cfg;
  int64_t K, D;
  torch::nn::Embedding token_embedding{nullptr};  // [K + 1, E]; row K = no token
  torch::nn::Embedding rate_embedding{nullptr};   // [3, emb]
  torch::nn::Linear time_fc1{nullptr}, time_fc2{nullptr};
  torch::nn::Conv2d conv_in{nullptr}, conv_out{nullptr};
  torch::nn::GroupNorm norm_out{nullptr};
  torch::nn::ModuleList down, up, token_proj, downsamplers, upsamplers;
  UNetLayer mid1{nullptr}, mid2{nullptr};
  std::vector<int> down_level, up_level;  // level of each layer in down / up
};
TORCH_MODULE(VideoUNet);

// Sinusoidal embedding of a scalar per row: [N] -> [N, dim].
torch::Tensor timestep_embedding(const torch::Tensor& t, int64_t dim);

}  // namespace gaia::decoder
