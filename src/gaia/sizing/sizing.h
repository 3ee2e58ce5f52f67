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
