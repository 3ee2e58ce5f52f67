#pragma once
// Shipping a tokenizer: weights in safetensors with the config YAML in the metadata, so a weights file is all
// `gaia tokenize` / `gaia tokenizer eval` need.
#include <opencv2/core.hpp>

#include "gaia/tokenizer/autoencoder.h"

namespace gaia::tokenizer {

void save_tokenizer(ImageTokenizer& t, const Config& c, const fs::path& path, bool half = false);
// Builds the model from the config stored in the file and loads the weights (on `device`, eval mode). Weights
// without a stored config (e.g. RUN/checkpoint/tokenizer.safetensors of an unfinished run) need `fallback`.
ImageTokenizer load_tokenizer(const fs::path& path, const torch::Device& device, Config* config_out = nullptr,
                              const Config* fallback = nullptr);

// RGB uint8 frames [N, H, W, 3] (the tokenizer's size, any strides) -> tokens [N, h, w] int64 on the CPU, in
// batches; and back: tokens [N, h, w] -> RGB uint8 frames [N, H, W, 3] on the CPU (the Python module's arrays).
torch::Tensor encode_rgb(ImageTokenizer& t, const torch::Tensor& rgb, const torch::Device& device);
torch::Tensor decode_rgb(ImageTokenizer& t, const torch::Tensor& tokens, const torch::Device& device);
// Encodes BGR frames (HxW of the tokenizer) to tokens [N, h, w] in batches.
torch::Tensor encode_frames(ImageTokenizer& t, const std::vector<cv::Mat>& frames, const torch::Device& device);
// Decodes tokens [N, h, w] to BGR frames.
std::vector<cv::Mat> decode_tokens(ImageTokenizer& t, const torch::Tensor& tokens, const torch::Device& device);

// A video file as a world model's prompt (`gaia generate --video`, `gaia sim --video`): up to `frames` frames at
// the world-model rate (the tokenizer's data.world_fps) and size, encoded: [frames, n] int64 on the CPU. Fails
// naming the file when the tokenizer gives other than `n` tokens a frame.
torch::Tensor video_prompt_tokens(ImageTokenizer& t, const Config& tok_cfg, const fs::path& video, int64_t frames,
                                  int64_t n, const torch::Device& device);

}  // namespace gaia::tokenizer
