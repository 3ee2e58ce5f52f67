#pragma once
// The one configuration of a gaia run, loaded from YAML (configs/*.yaml) plus --set key=value overrides.
// Every field is registered once (Config::visit) with its dotted key and a comment; loading, overrides,
// dumping and "unknown key" errors all go through that list, so a key cannot be half-supported.
// Defaults are the CPU-sized default config; configs/paper.yaml holds the paper's values (§4).
#include <cmath>
#include <cstdint>
#include <limits>
#include <functional>
#include <string>
#include <vector>

#include "gaia/core/fs.h"

namespace gaia {

// The values a numeric key allows (each entry, for a list): [lo, hi], either end open. Declared once per key in
// Config::fields() and checked wherever a value arrives: YAML files, --set, a weights file's stored config, and
// validate() for configs built in code. Upper bounds stop a typo from asking for the machine's whole memory.
struct Range {
  double lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
  bool lo_open = false, hi_open = false;
  bool contains(double v) const {
    return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
  }
  bool bounded() const { return std::isfinite(lo) || std::isfinite(hi); }
  std::string str() const;  // "[1, 1024]", "(0, 1]", "[0, inf)"
};

struct DataConfig {
  int height = 72;               // paper §4.1: 288 (default is 4x smaller for the CPU)
  int width = 128;               // paper §4.1: 512 (9/16 ratio)
  double native_fps = 25.0;      // paper §3: data at 25 Hz
  double world_fps = 6.25;       // paper §2.3: world model runs at 6.25 Hz
  std::vector<std::string> balance_tokenizer{"latitude", "longitude", "weather"};  // paper §3
  std::vector<std::string> balance_world{"latitude", "longitude", "weather", "steering", "speed"};  // paper §3
  double balance_exponent = 0.5;  // paper §3: 0 = empirical, 1 = uniform; 0.5 used for all features
  int balance_bins = 10;          // bins for continuous features
};

struct TokenizerConfig {
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
  // paper §4.1 loss weights
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
};

struct WorldConfig {
  // CPU-sized: a few M parameters, trainable on one CPU core (configs/paper.yaml holds the paper's 6.5B).
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
  // by more than a sign. The shipped model has none.
  int action_mlp = 0;
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
  int top_k = 50;                // paper §5.1 Fig. 5: top-k = 50
  double temperature = 1.0;
  // Logit added to the previous frame's token at the same position (t >= 1), in training, scoring and sampling. 0 =
  // the paper's model. `gaia world calibrate` fits it after training by maximum likelihood on training windows: a
  // small model under-predicts "this patch did not change" (it copies less than real video), and one scalar fitted
  // like temperature scaling (Guo et al. 2017) puts that probability where the data has it.
  double copy_bias = 0.0;
  bool guide_actions_within_top_k = true;  // action-guided tokens come from the conditional top k (world/sampling.h)
  double guidance_scale = 0.0;   // s in l = (1 + s) l_cond - s l_uncond (paper eq. 2)
};

struct DecoderConfig {
  // CPU-sized (~3M parameters, a few seconds a step on 2 cores at 72x128); paper.yaml is the 2.6B of §4.3.
  int channels = 32;             // base width of the 3D U-Net
  std::vector<int> channel_mult{1, 2, 4};
  int res_blocks = 1;
  std::vector<int> attn_levels{2};  // levels (0 = full resolution) that get spatial attention
  // Levels with temporal attention. Ho et al. (2022) use every level; at full resolution it is ~T' x H x W tiny
  // attention problems, a third of a CPU step, so the CPU default keeps it to the lower resolutions.
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
  double token_dropout = 0.15;   // paper §2.4: p = 0.15
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
  // steps). The CPU recipe trains 1300 steps at batch 2 (~2.5 h on one core), so it uses a 4x higher rate with
  // the same shape; the residual over the coarse frame (cond_image) is what makes so few steps enough.
  double lr = 2e-4, weight_decay = 0.01, beta1 = 0.9, beta2 = 0.99, grad_clip = 1.0, final_lr = 1e-5;
  int warmup_steps = 50, steps = 1300, batch_size = 2;
  // Cosine log-SNR shift (Hoogeboom et al. 2023): log-SNR + 2 log(shift); < 1 = noisier, for large frames (the
  // paper: 1). The CPU default diffuses the residual over the coarse frame, whose spread is ~1/5 of a frame's, so
  // at shift 1 most noise levels bury it; 4 moves them back to where the residual is visible (+2.8 in log-SNR).
  double schedule_shift = 4.0;
};

struct RunConfig {
  std::string device = "cpu";    // cpu | cuda | cuda:N
  int threads = 0;               // 0 = all cores
  uint64_t seed = 0;
  int checkpoint_every = 200;    // steps between checkpoints (resumable training)
};

struct Config {
  std::string name = "default";
  DataConfig data;
  TokenizerConfig tokenizer;
  WorldConfig world;
  DecoderConfig decoder;
  RunConfig run;

  // Derived quantities (paper §2.1, §4.2)
  int tokens_h() const { return data.height / tokenizer.downsample; }
  int tokens_w() const { return data.width / tokenizer.downsample; }
  int image_tokens() const { return tokens_h() * tokens_w(); }  // n; paper: 18 x 32 = 576
  int step_tokens() const { return world.text_tokens + image_tokens() + world.action_tokens; }  // m + n + l = 610
  int64_t sequence_length() const { return int64_t(world.context_steps) * step_tokens(); }  // paper: 15860

  // Registry: each field with its dotted key ("world.d_model").
  struct Field {
    std::string key, type;
    Range range;                                  // allowed values (numbers and int lists; unbounded otherwise)
    std::function<std::string()> get;            // YAML text of the value
    std::function<void(const std::string&)> set;  // parses YAML text; throws gaia::Error on a bad or out-of-range value
    std::function<void()> check;                  // throws gaia::Error if the current value is out of range
  };
  std::vector<Field> fields();

  static Config load(const fs::path& yaml);        // unknown keys -> "FILE: unknown config key 'a.b'"
  void apply_yaml(const std::string& text, const std::string& where);
  void set(const std::string& key_eq_value);        // --set world.d_model=512
  void validate() const;                            // every key's range, then cross-field checks (D divides H, W; ...)
  std::string to_yaml();
};

// A stored config's YAML `text` (e.g. a weights file's metadata) with one key set: "world.temperature=0.9", checked
// as --set checks it and the whole config validated. Only that key changes; keys the text lacks stay absent, so a
// loader still sees which keys the file was saved without (decoder/io.cpp gives those their legacy values).
std::string set_yaml_key(const std::string& text, const std::string& key_eq_value, const std::string& where);

}  // namespace gaia
