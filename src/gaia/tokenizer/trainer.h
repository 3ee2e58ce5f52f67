#pragma once
// `gaia tokenizer train` (§2.2, §4.1): balanced frames, the paper's loss weights (L1 0.2, L2 2.0, perceptual 0.1,
// GAN 1.0, codebook 1.0, DINO 0.1), AdamW with warm-up + cosine decay, dead-code restarts, periodic validation,
// checkpoints that resume exactly (batches and noise are functions of (seed, step)).
#include <functional>
#include <string>

#include <nlohmann/json.hpp>

#include "gaia/config.h"
#include "gaia/core/fs.h"
#include "gaia/train/distributed.h"

namespace gaia::tokenizer {

struct TrainOptions {
  fs::path dataset, out;          // OUT/checkpoint/ (resumable), OUT/tokenizer.safetensors, OUT/metrics.jsonl
  fs::path vgg, dino;             // teacher weights; empty = that loss is off (logged); a missing file is an error
  fs::path init;                  // start from these tokenizer weights (fine-tuning); ignored when resuming
  int steps = -1;                 // -1: config tokenizer.steps
  int val_every = 250;            // steps between validations
  int val_frames = 32;            // held-out frames scored at each validation
  int restart_every = 200;        // dead-code restart interval (0 = off)
  // Train the decoder alone: encoder and quantiser frozen, no codebook/DINO losses and no dead-code restarts, so
  // every frame keeps exactly the codes of the --init weights and token datasets made with them stay valid.
  bool decoder_only = false;
  int stop_after = -1;            // stop (with a checkpoint) after this many steps in this run; for tests
  // Data-parallel ranks, gradient accumulation, sharded optimiser state (train/distributed.h). Code usage is summed
  // over the ranks; rank 0 restarts dead codes and sends the codebook. Rank 0 alone writes OUT, validates, reports.
  train::Parallel parallel;
};

struct StepLog {
  int step = 0, total = 0;
  double lr = 0;
  nlohmann::json losses;          // named loss terms of this step
  bool validation = false;
  nlohmann::json val;             // psnr, ssim, usage, perplexity when validation
};

struct TrainResult {
  int final_step = 0;
  bool resumed = false;
  nlohmann::json last_val;
  std::vector<std::string> notes;  // e.g. "no DINO teacher: DINO loss off"
};

TrainResult train_tokenizer(const Config& config, const TrainOptions& opt,
                            const std::function<void(const StepLog&)>& on_step = {},
                            const std::function<void(const std::string&)>& on_note = {});

}  // namespace gaia::tokenizer
