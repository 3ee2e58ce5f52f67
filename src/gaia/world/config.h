#pragma once
// The world model's configuration (§2.1, §2.3, §4.2): YAML section `world:`. Part of gaia::Config (gaia/config.h).
// A weights file fixes the architecture and records the training settings; the sampling settings are stored with
// it as defaults that a run may override (--set, or flags such as --top-k).
#include <vector>

#include "gaia/core/config_registry.h"

namespace gaia {

struct WorldConfig {
  // Architecture. CPU-sized: a few M parameters, trainable on one CPU core (configs/paper.yaml holds the paper's 6.5B).
  int d_model = 192;             // d; paper §2.1: d = 4096
  int n_layers = 4;              // paper-scale 6.5B implies 32 layers at d = 4096 (12 d^2 per layer)
  int n_heads = 6;
  int context_steps = 8;         // T; paper §4.2: T = 26 steps at 6.25 Hz (4 s)
  int text_tokens = 16;          // m; paper §2.1: m = 32 T5-large tokens per step (synth captions: ~14 words)
  int text_dim = 128;            // width of text embeddings fed to the linear layer (T5-large: 1024)
  int text_vocab = 2048;         // built-in word vocabulary size
  int action_tokens = 2;         // l; paper §2.1: speed and curvature
  // Hidden units of a small MLP (1 -> h -> d, GELU) added to each action's linear layer; 0 = the paper's linear
  // layer alone (§2.1). A linear embedding is one direction scaled by the value; the MLP lets left and right differ
  // by more than a sign.
  int action_mlp = 0;
  // Logit added to the previous frame's token at the same position (t >= 1), in training, scoring and sampling. 0 =
  // the paper's model. `gaia world calibrate` fits it after training by maximum likelihood on training windows: a
  // small model under-predicts "this patch did not change" (it copies less than real video), and one scalar fitted
  // like temperature scaling (Guo et al. 2017) puts that probability where the data has it.
  double copy_bias = 0.0;
  // Added to copy_bias where the slot before (i - 1, this frame) kept its code too: unchanged codes come in runs
  // (static sky, road, a car ahead), and a model briefly trained on a few minutes spreads copies too evenly. Fitted
  // with copy_bias; 0 = one copy logit for every slot.
  double copy_bias_run = 0.0;

  // Training.
  double dropout = 0.0;
  // paper §4.2 conditioning mix: unconditional / action / text = 20% / 40% / 40%
  double p_uncond = 0.2, p_action = 0.4, p_text = 0.4;
  // Share of action-conditioned examples among windows of counterfactual replays (episodes with metadata replay_of,
  // `gaia synth counterfactuals`); the rest are unconditional or text-conditioned in the ratio above. -1 = the mix
  // above for every window. Replays show what a command does from a recorded state, so they teach action control;
  // raising action conditioning on them alone keeps every other window's share of text examples.
  double p_action_replay = -1;
  // paper §4.2 optimiser: AdamW lr 1e-4, wd 0.1, betas (0.9, 0.95), clip 1.0; 2.5k warm-up, cosine to lr/10
  // (batch 512 x 15860 tokens, 100k steps). The CPU recipe trains 3k steps of 4 x 1296 tokens, so, as for small
  // GPTs, a higher rate with the same shape.
  double lr = 6e-4, weight_decay = 0.1, beta1 = 0.9, beta2 = 0.95, grad_clip = 1.0, final_lr_ratio = 0.1;
  int warmup_steps = 100, steps = 3000, batch_size = 4;
  bool activation_checkpointing = false;  // paper §4.2 uses it with DeepSpeed ZeRO-2

  // Scaling-law study (§6, `gaia scaling`): model k = 0, 1, ... of the family has d_model = scaling_width x
  // scaling_growth^k rounded to a multiple of scaling_head_dim, n_heads = d_model / scaling_head_dim, n_layers =
  // max(1, round(d_model / scaling_width_per_layer)) (a fixed aspect ratio, as Kaplan et al. 2020), and trains on
  // scaling_tokens_per_param x N tokens (N: non-embedding parameters; Hoffmann et al. 2022 find about 20 optimal),
  // its warm-up and cosine decay fitted to its own length.
  int scaling_width = 16, scaling_head_dim = 16, scaling_width_per_layer = 48;
  double scaling_growth = 1.5, scaling_tokens_per_param = 20;

  // Sampling (§5.1).
  int top_k = 50;                // paper §5.1 Fig. 5: top-k = 50
  double temperature = 1.0;
  bool guide_actions_within_top_k = true;  // action-guided tokens come from the conditional top k (world/sampling.h)
  double guidance_scale = 0.0;   // s in l = (1 + s) l_cond - s l_uncond (paper eq. 2); `gaia generate`'s default
};

// The section's keys ("world.d_model", ...) with their roles and ranges, appended to `out`.
void add_config_fields(WorldConfig& c, std::vector<ConfigField>& out);

}  // namespace gaia
