#pragma once
// Shipping a video decoder: weights (the EMA copy, §4.3) in safetensors with the config YAML and the tokenizer's
// codebook size K and downsampling D in the metadata, so a weights file is all `gaia decode` needs besides tokens.
#include "gaia/config.h"
#include "gaia/decoder/unet.h"

namespace gaia::decoder {

void save_decoder(const VideoUNet& m, const Config& c, const fs::path& path, bool half = false);
// Builds the network from the stored config and loads the weights (on `device`, eval mode).
VideoUNet load_decoder(const fs::path& path, const torch::Device& device, Config* config_out = nullptr);

}  // namespace gaia::decoder
