#pragma once
// Sampling of the video decoder (§5.2): DDIM over one window of frames, with the paper's image/video mixing, and
// the windows of the full decoding schedule (backward autoregressive decoding at the token rate, then temporal
// upsampling 6.25 -> 12.5 -> 25 Hz by interpolation).
#include <functional>
#include <random>
#include <vector>

#include <torch/torch.h>

#include "gaia/decoder/diffusion.h"
#include "gaia/decoder/unet.h"
#include "gaia/torch/precision.h"

namespace gaia::decoder {

// The deterministic DDIM loop from z at time `start` (1 = pure noise) to t = 0 over `steps` uniform steps. v_fn(z, t)
// returns the v prediction at time t. Generic so that a test can run it with an analytic denoiser.
torch::Tensor ddim_loop(torch::Tensor z, int steps, const NoiseSchedule& sched,
                        const std::function<torch::Tensor(const torch::Tensor&, double)>& v_fn, double start = 1.0);

struct SampleOptions {
  int steps = 50;                // §5.2: 50 DDIM steps
  double mix_probability = 0.25;  // §5.2: per step, with this probability ...
  double mix_weight = 0.5;        // ... v = w v_image + (1 - w) v_video (temporal layers off for v_image), on the
                                  // frames that have tokens (an interpolated frame has nothing to be an image of)
  // Share part of the starting noise between the frames of a window: z_T = sqrt(r) n_shared + sqrt(1 - r) n_frame
  // (each frame's noise stays N(0, I); frames are correlated by r). DDIM is deterministic from z_T, so detail that
  // the tokens leave open is drawn alike in neighbouring frames instead of independently (cf. the correlated noise
  // prior of Ge et al. 2023, used here at sampling time only). 0 = independent noise, as in training.
  double noise_correlation = 0.0;
  // Temperature of the starting noise: z_T = s n. Below 1, DDIM lands nearer the model's mean residual over the
  // coarse frame instead of a full draw of the detail the tokens leave open: a draw's error is that of the mean
  // plus the draw's own spread, and the spread is drawn anew in every frame (flicker). 1 = the paper's sampler,
  // 0 = the deterministic path from z_T = 0. Sampling only; training is unchanged.
  double noise_scale = 1.0;
  // The time DDIM starts from. 1 = the paper's sampler (z_1 is pure noise). Below 1 the window starts at
  // z = sigma(start) s n, i.e. a zero residual over the coarse frame noised to that level (SDEdit, Meng et al.
  // 2022): the coarse frame's content is kept and only detail finer than the noise level is redrawn, so fewer
  // model calls are spent on what the tokens already fix. Every generated frame needs a coarse frame
  // (cond_image, and interp_base for frames without tokens); the frame itself would otherwise start from grey.
  double start_time = 1.0;
  uint64_t seed = 0;
  // The denoiser's products (--precision): bf16 runs the U-Net under autocast (its norms and the DDIM update stay
  // float32), on a CPU with bf16 instructions faster at the same PSNR (docs/benchmarks.md).
  Precision precision = Precision::kFp32;
};

// The starting noise z_T of a window, sizes = [B, T, ...], drawn on the CPU from gen: N(0, I) per frame, and
// correlation r between any two frames of a window (SampleOptions::noise_correlation); r = 0 is plain randn.
torch::Tensor starting_noise(at::IntArrayRef sizes, double correlation, at::Generator& gen);

// The sampling options a decoder config sets (§5.2 mixing, noise correlation); steps <= 0 -> cfg.ddim_steps.
SampleOptions sample_options(const DecoderConfig& cfg, int steps, uint64_t seed);

// One window: context frames are kept as given, the others are generated.
struct WindowInput {
  torch::Tensor frames;      // [B, T, 3, H, W] clean frames where context, anything elsewhere
  torch::Tensor context;     // [B, T] float, 1 = context
  torch::Tensor tokens;      // [B, T, h, w] int64, K where a frame has no tokens
  torch::Tensor cond_image;  // [B, T, 3, H, W] (zeros where no tokens); may be undefined if the model has no cond_image
  int rate = 0;              // tasks.h kRates index of this window's frames
  bool temporal = true;
};
// -> [B, T, 3, H, W] in [-1, 1]. The paper mixes eps; v and eps are affine in each other at a fixed x_t and t, so
// mixing v with the same weights is the same thing.
torch::Tensor sample_window(VideoUNet& model, const NoiseSchedule& sched, const WindowInput& in, const SampleOptions& o);

// A window of the decoding schedule over a sequence of frames.
struct Window {
  int64_t start = 0;           // first frame of the sequence in the window
  std::vector<bool> context;   // per window frame: already known (given clean)
};
// §5.2, backwards: decode the last T' frames, then windows of T' frames ending with kOverlapFrames = 2 already decoded
// frames, moving towards the start (the first window may then hold more context frames). N < T' -> one window.
std::vector<Window> backward_windows(int64_t N, int T);
// Upsampling of a sequence of M = 2N - 1 frames whose even positions are known: windows of T' (odd) frames that
// start and end on known frames; the last one may be shorter.
std::vector<Window> upsample_windows(int64_t M, int T);

}  // namespace gaia::decoder
