#pragma once
// Token sequence -> video (§5.2): decode the frames at the token rate backwards in overlapping windows, then
// upsample twice in time by interpolation (6.25 -> 12.5 -> 25 Hz with the default rates).
#include <functional>

#include <torch/torch.h>

#include "gaia/decoder/sampler.h"

namespace gaia::decoder {

struct DecodeOptions {
  SampleOptions sample;
  double token_fps = 6.25;   // rate of the token frames (one of tasks.h kRates)
  double out_fps = 25.0;     // stop upsampling at this rate (token_fps, or 2x / 4x it)
};

// Number of windows decode_video will denoise (for progress bars and time estimates).
int count_windows(int64_t N, int frames, double token_fps, double out_fps);

// tokens [B, N, h, w] int64 in [0, K); cond [B, N, 3, H, W] tokenizer-decoded frames (undefined unless the model
// was trained with cond_image) -> [B, M, 3, H, W] in [-1, 1], M = N, 2N - 1 or 4N - 3.
// progress(done_windows, total_windows).
torch::Tensor decode_video(VideoUNet& model, const NoiseSchedule& sched, const torch::Tensor& tokens,
                           const torch::Tensor& cond, const DecodeOptions& o,
                           const std::function<void(int, int)>& progress = {});

// Frames [M, 3, H, W] at rate r -> [2M - 1, ...] at 2r: even positions known, odd ones generated (also used alone
// to upsample any clip).
torch::Tensor upsample_video(VideoUNet& model, const NoiseSchedule& sched, const torch::Tensor& frames, int out_rate,
                             const SampleOptions& o, const std::function<void()>& on_window = {});

}  // namespace gaia::decoder
