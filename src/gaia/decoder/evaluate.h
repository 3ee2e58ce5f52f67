#pragma once
// `gaia decoder eval` (§5.2 targets): held-out clips decoded from their true tokens by the video diffusion decoder
// and by the tokenizer's own frame-by-frame decoder; per-frame PSNR against the real frames and temporal flicker,
// at the token rate and at 25 Hz, for several DDIM step counts, with timings.
#include <functional>
#include <vector>

#include <nlohmann/json.hpp>

#include "gaia/config.h"
#include "gaia/decoder/unet.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/torch/precision.h"
#include "gaia/world/footage.h"

namespace gaia::decoder {

// Mean absolute difference between consecutive frames (0-255 scale), averaged over the sequence; frames [M, 3, H, W]
// in [-1, 1]. The flicker is this for the generated frames minus this for the ground truth.
double temporal_change(const torch::Tensor& frames);
// Mean absolute difference between the generated and the true frame-to-frame change, |(g[t+1] - g[t]) -
// (x[t+1] - x[t])| (0-255 scale): temporal inconsistency that motion does not explain. The flicker is a
// difference of magnitudes, so a decoder whose frames are blurred (changing less than the truth) scores below 0
// however much its errors jump from frame to frame; this one counts those jumps, and is 0 only when every change
// is the true one.
double temporal_error(const torch::Tensor& frames, const torch::Tensor& truth);
// Mean absolute difference between horizontally and vertically neighbouring pixels (0-255 scale), frames [..., H, W]
// in [-1, 1]: how much fine detail the frames hold. Reported as the ratio to the ground truth's (1 = as sharp as
// the real frames): PSNR rewards the blur of a mean prediction, and this shows what that blur costs.
double edge_energy(const torch::Tensor& frames);
// Frames at `factor` times the rate of `key` [N, ...] by linear blending of neighbouring key frames -> [(N - 1) factor
// + 1, ...]; the key frames are kept. A frame-by-frame decoder that gets tokens only at the token rate (6.25 Hz)
// reaches 25 Hz this way: the baseline the video decoder's upsampling must beat.
torch::Tensor blend_to_rate(const torch::Tensor& key, int factor);
// PSNR between images in [-1, 1] (the first is clamped), on the [0, 1] scale.
double psnr_pm1(const torch::Tensor& a, const torch::Tensor& b);

// Tokens a world model generates for a clip: the clip's own token frames [N, h, w] at 6.25 Hz and the recorded
// (speed m/s, curvature 1/m) at each [N, 2] -> [N, h, w], the frames after the prompt replaced by generated ones.
// The paper's reason for a video decoder is decoding such tokens (§2.4), which need not agree from frame to frame.
using TokenGenerator = std::function<torch::Tensor(const torch::Tensor& tokens, const torch::Tensor& actions)>;

struct DecoderEvalOptions {
  int clips = 2;                   // held-out clips
  world::Footage footage = world::Footage::kAny;  // held-out drives of this footage only (real: recorded cameras)
  int token_frames = 8;            // N token frames at 6.25 Hz per clip (-> 4N - 3 frames at 25 Hz)
  std::vector<int> steps{50, 20, 10};  // DDIM step counts to compare (§5.2 uses 50)
  // Rate of the tokens the video decoder is given: 6.25 Hz (the world model's rate; the decoder upsamples to 25 Hz,
  // §5.2), 12.5, or 25 (every frame's own tokens, as the tokenizer decoder gets them at 25 Hz).
  double token_fps = 6.25;
  uint64_t seed = 0;
  Precision precision = Precision::kFp32;  // the video decoder's (SampleOptions::precision); the baselines stay float32
  // Set: both decoders decode generated tokens instead of the true ones (token_fps must be 6.25). PSNR is then
  // against the recorded future, one of many; flicker still compares each decoder's change with the truth's.
  TokenGenerator generate;
};

nlohmann::json evaluate_decoder(const Config& decoder_config, VideoUNet& model, tokenizer::ImageTokenizer& tok,
                                const fs::path& dataset, const DecoderEvalOptions& o,
                                const std::function<void(int, int)>& progress = {});

}  // namespace gaia::decoder
