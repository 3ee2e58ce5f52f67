#pragma once
// `gaia tokenizer eval`: reconstruction quality (PSNR, SSIM) and code statistics (usage, perplexity) of a tokenizer
// on a set of frames, overall and per group (weather, time of day), since one average hides where the bits go:
// rain and snow streaks are noise no 10-bit code per 8x8 patch can keep.
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/tokenizer/autoencoder.h"

namespace gaia::tokenizer {

// What a frame is grouped by, e.g. {"weather": "rain", "time_of_day": "dusk"}; empty values are not grouped.
using FrameTags = std::map<std::string, std::string>;

// frames (BGR, the tokenizer's size) and their tags (empty, or one per frame) ->
//   {"frames", "psnr", "ssim", "code_usage", "code_perplexity", "bit_compression",
//    "by_<tag>": {"<value>": {"frames", "psnr", "ssim"}, ...}, ...,
//    "by_clip": {"<footage>": {"episodes", "median_psnr", "worst_psnr", "worst_episode"}}  (with "episode" tags)}
// progress(frames done) after each batch.
nlohmann::json evaluate_reconstruction(ImageTokenizer& t, const Config& c, const std::vector<cv::Mat>& frames,
                                       const std::vector<FrameTags>& tags, const torch::Device& device,
                                       const std::function<void(int64_t)>& progress = {});

}  // namespace gaia::tokenizer
