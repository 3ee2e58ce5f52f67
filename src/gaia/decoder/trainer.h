#pragma once
// `gaia decoder train` (§2.4, §4.3): multi-task training of the video diffusion decoder on clips of T' frames at
// 6.25, 12.5 or 25 Hz, conditioned on the tokens of a frozen image tokenizer; v-parameterisation, 0.1 L1 + 1.0 L2,
// EMA 0.999, AdamW with warm-up + cosine decay; checkpoints that resume exactly.
#include <functional>
#include <memory>
#include <random>
#include <string>

#include <nlohmann/json.hpp>

#include "gaia/config.h"
#include "gaia/data/episode.h"
#include "gaia/decoder/diffusion.h"
#include "gaia/decoder/tasks.h"
#include "gaia/decoder/unet.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/train/distributed.h"

namespace gaia::decoder {

// Clips of frames with their tokens (and the tokenizer's decoded frames when the decoder uses them).
struct Clips {
  torch::Tensor frames;  // [B, T, 3, H, W] in [-1, 1]
  torch::Tensor tokens;  // [B, T, h, w] int64
  torch::Tensor cond;    // [B, T, 3, H, W] or undefined
};
struct ClipRef {
  size_t episode;               // position in the episode list
  std::vector<int64_t> frames;  // frame indices
};
Clips load_clips(const std::vector<std::unique_ptr<data::Episode>>& episodes, const std::vector<ClipRef>& refs,
                 tokenizer::ImageTokenizer& tok, bool with_cond, const torch::Device& dev);

// A training example of a task: what the network sees and the loss weights. Token dropout (§2.4, p = 0.15) replaces
// tokens by the "no token" id K and blanks the matching D x D patch of the decoded frame.
struct TaskBatch {
  DenoiserInput input;
  torch::Tensor v_true;  // [B, T, 3, H, W]
  torch::Tensor weight;  // [B, T] 1 = frame carries loss
};
// interp_base: frames with neither tokens nor context get the blend of their context neighbours as their coarse
// frame (config decoder.interp_base; diffusion.h interpolation_base).
TaskBatch make_task_batch(const Clips& clips, const FrameMasks& masks, int rate, double t, double token_dropout,
                          const NoiseSchedule& sched, int64_t K, int64_t D, bool interp_base = false);

struct DecoderTrainOptions {
  fs::path dataset, tokenizer, out;  // OUT/checkpoint/, OUT/decoder.safetensors (EMA weights), OUT/metrics.jsonl
  fs::path init;                     // fine-tuning: start model and EMA from these weights (ignored when resuming)
  int steps = -1;                    // -1: config decoder.steps
  int val_every = 250;
  int val_clips = 8;
  int stop_after = -1;               // stop (with a checkpoint) after this many steps in this run; for tests
  // Data-parallel ranks, gradient accumulation, sharded optimiser state (train/distributed.h): each rank loads its
  // own clips of the step's batch. Rank 0 alone writes OUT, validates and reports.
  train::Parallel parallel;
};

struct DecoderStepLog {
  int step = 0, total = 0;
  double lr = 0, loss = 0, grad_norm = 0, seconds = 0;
  std::string task;
  bool validation = false;
  nlohmann::json val;
};

struct DecoderTrainResult {
  int final_step = 0;
  bool resumed = false;
  nlohmann::json last_val;
};

DecoderTrainResult train_decoder(const Config& config, const DecoderTrainOptions& opt,
                                 const std::function<void(const DecoderStepLog&)>& on_step = {},
                                 const std::function<void(const std::string&)>& on_note = {});

}  // namespace gaia::decoder
