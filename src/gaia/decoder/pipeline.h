#pragma once
// Tokens to pixels the whole way, shared by `gaia decode` and `gaia demo`: the tokenizer's decoding of every token
// frame (the --fast preview, and the coarse frame the CPU decoder is conditioned on), then the video diffusion
// decoder's backward autoregressive decoding and temporal upsampling (§5.2) when a decoder is given.
#include <functional>
#include <vector>

#include <opencv2/core.hpp>
#include <torch/torch.h>

#include "gaia/decoder/video.h"
#include "gaia/tokenizer/autoencoder.h"

namespace gaia::decoder {

// Token ids [F, N, h, w] (F futures of N frames) -> the tokenizer decoder's frames [F, N, 3, H, W] in [-1, 1].
torch::Tensor coarse_frames(tokenizer::ImageTokenizer& tok, const torch::Tensor& ids, const torch::Device& dev);

// Video decoder on [F, N, h, w] tokens at token_fps -> [F, M, 3, H, W] at out_fps (M = N, 2N - 1 or 4N - 3).
// `steps` <= 0 uses the decoder's configured DDIM steps. Errors name `weights` when the decoder does not fit the
// tokenizer (K, D). `configure`, when given, adjusts the config read from `weights` before sampling (the user's
// sampling overrides, e.g. decoder.noise_correlation).
torch::Tensor diffusion_decode(tokenizer::ImageTokenizer& tok, const fs::path& weights, const torch::Tensor& ids,
                               const torch::Tensor& coarse, int steps, double token_fps, double out_fps, uint64_t seed,
                               const torch::Device& dev, const std::function<void(int, int)>& progress = {},
                               const std::function<void(Config&)>& configure = {},
                               Precision precision = Precision::kFp32);

// [F, M, 3, H, W] -> M BGR frames with the F futures side by side.
std::vector<cv::Mat> side_by_side(const torch::Tensor& video);

}  // namespace gaia::decoder
