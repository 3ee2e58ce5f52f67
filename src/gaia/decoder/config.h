#pragma once
// The video diffusion decoder's configuration (§2.4, §4.3, §5.2): YAML section `decoder:`. Part of gaia::Config
// (gaia/config.h). A weights file fixes the architecture; the sampling settings are stored with it as defaults
// that a run may override.
#include <vector>

#include "gaia/core/config_registry.h"

namespace gaia {

struct DecoderConfig {
  // Architecture. CPU-sized (a few M parameters at 72x128); paper.yaml is the 2.6B of §4.3.
  int channels = 32;             // base width of the 3D U-Net
  std::vector<int> channel_mult{1, 2, 4};
  int res_blocks = 1;
  std::vector<int> attn_levels{2};  // levels (0 = full resolution) that get spatial attention
  // Levels with temporal attention. Ho et al. (2022) use every level; at full resolution it is T' x H x W tiny
  // attention problems, costly on a CPU, so the CPU default keeps it to the lower resolutions.
  std::vector<int> temporal_levels{1, 2};
  int heads = 4;
  int token_embed_dim = 64;      // conditioning token embedding width
  // Also condition on the tokenizer decoder's image of the tokens (a coarse frame, as in cascaded diffusion): the
  // diffusion model then diffuses the residual over that image (diffusion.h coarse_base) and learns detail and
  // temporal consistency rather than the whole image, which a CPU-sized model can learn in hours. The paper
  // conditions on tokens alone (paper.yaml: false).
  bool cond_image = true;
  // With cond_image: a frame with neither tokens nor context (the frames between known ones when upsampling
  // 6.25 -> 12.5 -> 25 Hz) gets as its coarse frame the blend of its nearest context frames in time
  // (diffusion.h interpolation_base), so the model refines a blend of its neighbours instead of drawing the whole
  // frame from noise. Decoders saved before this option existed load with it off (they were trained without).
  bool interp_base = true;
  int frames = 7;                // T'; paper §4.3: T' = 7
  // Cosine log-SNR shift (Hoogeboom et al. 2023): log-SNR + 2 log(shift); < 1 = noisier, for large frames (the
  // paper: 1). The CPU default diffuses the residual over the coarse frame, whose spread is a fraction of a frame's,
  // so at shift 1 most noise levels bury it; a larger shift moves them back to where the residual is visible.
  double schedule_shift = 4.0;

  // Training.
  double token_dropout = 0.15;   // paper §2.4: p = 0.15
  // Training draws each window's noise level t ~ U(0, train_max_time) (paper: 1, every level). A sampler that
  // starts at start_time < 1 never asks the model about t above it, so a CPU-sized model can spend all of its
  // training on the levels it is sampled at.
  double train_max_time = 1.0;
  double w_l1 = 0.1, w_l2 = 1.0;  // paper §4.3
  // Weight of a temporal-consistency term (not in the paper; 0 = its loss): diffusion.h temporal_v_loss, the change
  // of the v error between consecutive predicted frames. An error that stays put costs less than one that changes
  // from frame to frame, which is what the eye sees as flicker.
  double w_temporal = 0.0;
  double ema_decay = 0.999;      // paper §4.3
  // paper §4.3 optimiser: AdamW lr 5e-5, wd 0.01, betas (0.9, 0.99), clip 1.0; cosine to 1e-6 (batch 64, 300k
  // steps). The CPU recipe trains 1300 steps at batch 2, so it uses a 4x higher rate with the same shape; the
  // residual over the coarse frame (cond_image) is what makes so few steps enough.
  double lr = 2e-4, weight_decay = 0.01, beta1 = 0.9, beta2 = 0.99, grad_clip = 1.0, final_lr = 1e-5;
  int warmup_steps = 50, steps = 1300, batch_size = 2;

  // Sampling (§5.2).
  int ddim_steps = 50;           // paper §5.2: 50 DDIM steps
  double mix_probability = 0.25, mix_weight = 0.5;  // paper §5.2 image/video eps mixing
  double noise_correlation = 0.0;  // sampler.h SampleOptions: starting noise shared between a window's frames
  // sampler.h SampleOptions: temperature of the starting noise (paper: 1). A colder start keeps a small decoder's
  // frames closer to the truth and steadier in time.
  double noise_scale = 0.5;
  // sampler.h SampleOptions: the noise level DDIM starts from (paper: 1, pure noise). Below 1 (needs cond_image)
  // the residual over the coarse frame starts at zero, noised to this level, so the sampler refines the coarse
  // frame instead of drawing its detail from scratch (SDEdit, Meng et al. 2022), which a CPU-sized decoder does
  // better at few DDIM steps as well as many.
  double start_time = 0.3;
};

// The section's keys ("decoder.channels", ...) with their roles and ranges, appended to `out`.
void add_config_fields(DecoderConfig& c, std::vector<ConfigField>& out);

}  // namespace gaia
