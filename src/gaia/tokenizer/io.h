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

// Encodes BGR frames (HxW of the tokenizer) to tokens [N, h, w] in batches.
torch::Tensor encode_frames(ImageTokenizer& t, const std::vector<cv::Mat>& frames, const torch::Device& device);
// Decodes tokens [N, h, w] to BGR frames.
std::vector<cv::Mat> decode_tokens(ImageTokenizer& t, const torch::Tensor& tokens, const torch::Device& device);

}  // namespace gaia::tokenizer
