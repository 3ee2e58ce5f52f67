#pragma once
// `gaia tokenize`: an episode dataset -> token episodes at the world-model rate (§2.3: 25 Hz -> 6.25 Hz), with the
// actions (speed, curvature) and captions aligned to each step. Format (docs/formats.md, "Token dataset"):
//   TOKENS/dataset.json                 {"format": "gaia-tokens", "schema_version": 1, "rate_hz", "grid": [h, w], ...}
//   TOKENS/episodes/<id>/tokens.npy     int16 [T, h, w]
//   TOKENS/episodes/<id>/actions.npy    float32 [T, 2] (speed m/s, curvature 1/m), mean over the step; NaN = missing
//   TOKENS/episodes/<id>/time_s.npy     float64 [T]
//   TOKENS/episodes/<id>/captions.jsonl T JSON strings; labels.jsonl (optional) T JSON objects
//   TOKENS/episodes/<id>/episode.json   the source episode's metadata + "frames": the source frame indices
//   TOKENS/split.json                   a copy of DATASET/split.json when there is one (geofenced validation)
// Episodes are staged and renamed, so an interrupted run resumes by skipping finished episodes.
// With `mirror`, each episode is also written in mirror image as `<id>-mirror` (data/mirror.h: flipped frames,
// negated curvature, left/right swapped in captions and labels), which balances left and right steering.
#include <functional>

#include <opencv2/core.hpp>
#include <torch/torch.h>

#include "gaia/tokenizer/autoencoder.h"

namespace gaia::tokenizer {

struct TokenizeResult {
  int64_t episodes_written = 0, episodes_skipped = 0, steps = 0;
};

TokenizeResult tokenize_dataset(const fs::path& dataset, const fs::path& weights, const fs::path& out, double rate_hz,
                                const torch::Device& device, const std::function<void(int64_t, int64_t)>& progress = {},
                                bool mirror = false);

// Fig. 3 of the paper: frames next to the top-3 PCA components of their code vectors as RGB (nearest-upsampled).
cv::Mat pca_sheet(ImageTokenizer& t, const std::vector<cv::Mat>& frames, const torch::Device& device);

}  // namespace gaia::tokenizer
