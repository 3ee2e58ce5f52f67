#pragma once
// The image tokenizer's configuration (§2.2, §4.1): YAML section `tokenizer:`. Part of gaia::Config (gaia/config.h).
#include <vector>

#include "gaia/core/config_registry.h"

namespace gaia {

struct TokenizerConfig {
  // Architecture.
  int downsample = 8;            // D; paper §4.1: D = 16
  int codebook_size = 1024;      // K; paper §4.1: K = 8192
  int code_dim = 16;             // low-dimensional code space (Yu et al. 2022 factorised codes)
  int channels = 32;             // base width of the encoder/decoder (CPU-sized; paper scale: see paper.yaml)
  std::vector<int> channel_mult{1, 2, 2, 4};  // one entry per resolution level; log2(D) downsamplings
  int res_blocks = 1;            // ResNet blocks per level (the decoder uses one more)
  // Extra ResNet blocks at full resolution at the end of the decoder (not in the paper). Their last convolution starts
  // at zero, so they can be added to trained weights without changing a single output, then trained with the
  // encoder frozen (`--decoder-only`): more reconstruction capacity where the error is, same codes.
  int refine_blocks = 0;
  // Extra ResNet blocks at the token grid at the start of the decoder (not in the paper), zero-initialised like
  // refine_blocks. At H/D x W/D they are cheap (1/D^2 of the pixels) and widen what each output pixel sees of the
  // neighbouring codes, which is where a decoder of fixed codes still has error to remove.
  int token_blocks = 0;
  int z_channels = 128;          // width at the bottleneck before the code projection
  int disc_channels = 32;        // PatchGAN discriminator width
  int disc_layers = 3;

  // Training. paper §4.1 loss weights:
  double w_l1 = 0.2, w_l2 = 2.0, w_perceptual = 0.1, w_gan = 1.0, w_codebook = 1.0, w_dino = 0.1;
  double commitment = 0.25;      // van den Oord et al. beta
  int disc_start = 2400;         // GAN loss switched on after this many steps (last fifth of the CPU recipe)
  // VQGAN (Esser et al. 2021) balance: the GAN gradient at the decoder's last layer is scaled to the size of the
  // reconstruction gradient there, times w_gan. Without it w_gan = 1.0 swamps L1/L2 at CPU batch sizes.
  bool gan_adaptive = true;
  // paper §4.1 optimiser: AdamW lr 1e-4, wd 0.01, betas (0.5, 0.9); 5k warm-up, cosine to 1e-5 (batch 160, 200k
  // steps). The CPU recipe trains 3k steps at batch 8, so it uses a 3x higher rate with the same shape.
  double lr = 3e-4, weight_decay = 0.01, beta1 = 0.5, beta2 = 0.9, final_lr = 3e-5;
  int warmup_steps = 100, steps = 3000, batch_size = 8;
  // Exponential moving average of the decoder's weights (not in the paper; 0 = off). The saved tokenizer decodes
  // with the average and encodes with the trained encoder and codebook, so the codes are those of training; at the
  // end of a fine-tune the average is a better decoder of them than the last noisy step (batch 8 on a CPU).
  double ema_decay = 0;
  // Share of each training batch darkened (tokenizer/augment.h; not in the paper, 0 = off): codes for nights darker
  // than the training drives.
  double augment_dark = 0;
};

// The section's keys ("tokenizer.downsample", ...) with their roles and ranges, appended to `out`.
void add_config_fields(TokenizerConfig& c, std::vector<ConfigField>& out);

}  // namespace gaia
