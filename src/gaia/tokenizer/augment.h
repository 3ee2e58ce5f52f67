#pragma once
// Photometric augmentation of the tokenizer's training frames. Not in the paper: a CPU-sized dataset's drives rarely
// reach the near-black of an unlit road at night, and a tokenizer that never saw such frames has no codes for them
// (it decodes black as dark grey), so a share of each batch is darkened the way a camera at night records a scene.
#include <torch/torch.h>

namespace gaia::tokenizer {

// x: frames [B, 3, H, W] in [-1, 1]. Each frame with probability `share` becomes gain * v^gamma in [0, 1] terms
// (v = (x + 1) / 2; gamma ~ U(1, 3) darkens the mid-tones more than the lights, gain ~ U(0.2, 1)), drawn from
// torch's generator; the others are returned as they are. Never brighter: every value stays <= its own.
torch::Tensor darken_some(const torch::Tensor& x, double share);

}  // namespace gaia::tokenizer
