#pragma once
// `gaia plan`: what a config costs before anything is built. Parameter counts come from closed-form
// formulas that mirror the module constructors (each component's test checks formula == numel of the module),
// so the paper's 6.5B configuration can be planned on a laptop without allocating it.
#include <cstdint>
#include <string>
#include <vector>

#include "gaia/config.h"

namespace gaia::sizing {

struct ParamCount {
  int64_t total = 0;
  int64_t non_embedding = 0;  // Kaplan et al.'s N, used for C = 6N (paper §6)
};

ParamCount tokenizer_params(const Config& c);      // encoder + quantiser + decoder (+ DINO head)
int64_t discriminator_params(const Config& c);     // PatchGAN, training only
ParamCount world_params(const Config& c);
ParamCount decoder_params(const Config& c);        // 3D U-Net video diffusion decoder

struct Plan {
  ParamCount tokenizer, world, decoder;
  int64_t discriminator = 0;
  int image_tokens = 0;          // n
  int64_t sequence_length = 0;   // T (m + n + l)
  double bit_compression = 0;    // H W 3 8 / (n log2 K)   (paper §4.1: ~470)
  double world_flops_per_token = 0;            // 6N (paper §6)
  double world_flops_per_token_with_attn = 0;  // 6N + 6 L s d (Kaplan et al. 2020, attention term)
  double world_weights_gb = 0;        // fp32 weights
  double world_train_state_gb = 0;    // mixed precision: bf16 weights + grads, fp32 master + Adam m, v (16 B/param)
  double world_act_gb_per_seq = 0;    // activations for one sequence, bf16, FlashAttention (no s^2 term)
  double world_act_ckpt_gb_per_seq = 0;  // with activation checkpointing (layer inputs + one layer)
  double tokenizer_weights_gb = 0, decoder_weights_gb = 0;
};

Plan make_plan(const Config& c);

// Inference arithmetic, to set a measured time against a machine's peak (docs/benchmarks.md): FLOPs of the
// matrix products and attention's two products (a multiply-add is 2), counted from the config as the parameter
// counts are. Norms, activations and softmax are left out, so time at the peak is a lower bound.
struct InferenceFlops {
  double world_token = 0;           // one image token of one row through every block and the head, full context
  double world_frame_sampling = 0;  // a frame sampled in a full window: its text, n tokens and actions, all rows
  double world_frame_reencode = 0;  // §2.3's one-step slide: the T - 1 kept steps encoded again, all rows (causal)
  double decoder_window = 0;        // one U-Net forward over a window of T' frames at data.height x data.width
  // One second of video at four times the token rate (25 Hz from 6.25), in the long run (§5.2's schedule:
  // backward windows at the token rate, then two doublings by interpolation), decoder.ddim_steps forwards a
  // window, one more at decoder.mix_probability where a window's frames have tokens (image/video mixing).
  double decoder_video_second = 0;
};
// `rows`: 2 where classifier-free guidance runs a conditional and an unconditional row, else 1.
InferenceFlops inference_flops(const Config& c, int rows);

// The memory one rank holds at its peak while training the world model, term by term (bytes), for a run's own
// settings: `gaia plan --nproc --accumulate --shard-optimizer --shard-gradients` prints it, and `world train` reports it beside the
// peak it measures. The peak falls at the start of the backward pass, with every saved activation and the output
// distribution's gradients alive, on top of last step's gradients and AdamW's moments.
struct TrainMemorySettings {
  int64_t micro_batch = 1;       // sequences per forward pass: world.batch_size / (ranks x accumulate)
  int ranks = 1;
  bool shard_optimizer = false;  // AdamW's moments divided over the ranks (ZeRO-1)
  bool shard_gradients = false;  // and the kept gradients with their buckets (ZeRO-2)
  int activation_bytes = 4;      // 4: float32; 2: bf16 / fp16 autocast
  bool fused_attention = false;  // scaled_dot_product_attention (LibTorch >= 2): no s^2 probabilities kept
  bool checkpointing = false;    // world.activation_checkpointing
};
struct TrainMemory {
  double weights = 0, grads = 0, optimizer = 0, buckets = 0, activations = 0, logits = 0;
  double beyond_weights() const { return grads + optimizer + buckets + activations + logits; }
  double total() const { return weights + beyond_weights(); }
};
// The settings of a run of `c` with `ranks` and `accumulate`, on this build (fused attention where LibTorch has it).
TrainMemorySettings train_memory_settings(const Config& c, int ranks, int accumulate, bool shard_optimizer,
                                          bool fused_attention, bool shard_gradients = false);
TrainMemory world_train_memory(const Config& c, const TrainMemorySettings& m);
std::string format_train_memory(const TrainMemory& t, const TrainMemorySettings& m);  // one table for the CLI

// This process's resident memory now, and the most it has held since it started (bytes; 0 where unknown).
double resident_bytes();
double peak_resident_bytes();

// Memory a rollout of `futures` futures over `steps` steps holds at its peak: the KV cache of every layer over
// the context (times `passes`: 2 or 3 with classifier-free guidance), the logits of a token, the output tokens and,
// with `preview`, the decoded preview frames.
double rollout_memory_bytes(const Config& c, int64_t futures, int64_t steps, int passes, bool preview);

// Bytes of memory available to this process now (MemAvailable); 0 when the system does not say.
double available_memory_bytes();

// Fails with one line saying what `what` would need against what is available, when it cannot fit.
void check_memory(double bytes, const std::string& what);
std::string format_plan(const Plan& p, const Config& c);  // human-readable table for the CLI

}  // namespace gaia::sizing
