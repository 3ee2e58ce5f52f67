#pragma once
// `gaia world train` (§2.3, §4.2): windows of T steps from a token dataset, balanced (§3), each example
// unconditional / action- / text-conditioned (20/40/40), cross-entropy on image tokens, AdamW (lr 1e-4, wd 0.1,
// betas 0.9/0.95), gradient clipping 1.0, warm-up then cosine decay to lr/10, validation on the geofenced
// held-out episodes, checkpoints that resume exactly, metrics to OUT/metrics.jsonl.
#include <functional>
#include <string>

#include <nlohmann/json.hpp>

#include "gaia/config.h"
#include "gaia/train/distributed.h"
#include "gaia/world/token_file.h"
#include "gaia/core/fs.h"

namespace gaia::world {

struct WorldTrainOptions {
  fs::path tokens, out;       // OUT/checkpoint/ (resumable), OUT/world.safetensors (last), OUT/best.safetensors
                              // (best validation, with best.json), OUT/metrics.jsonl
  TokenFormat format;         // for other tokenizers' files; K unstated = the config's tokenizer.codebook_size
  fs::path init;              // fine-tuning: start from these weights (and keep their text vocabulary)
  // The text the model reads (§2.1). Auto: --init's kind, else the dataset's embeddings where it has them, else
  // the built-in words. Words: the built-in words even when the dataset has embeddings. Embeddings: the dataset's
  // (gaia text embed, or made elsewhere).
  enum class Text { Auto, Words, Embeddings };
  Text text = Text::Auto;
  // Fine-tuning: the text path (word_embedding, text_proj) starts afresh instead of from --init, with a vocabulary
  // of this dataset's words. Implied when `text` gives the model another text than --init's (another encoder).
  bool fresh_text = false;
  int steps = -1;             // -1: config world.steps
  // Steps between validations; -1: 250, or two passes over the training data where that comes sooner (at least 25):
  // a small set overfits within a few hundred steps, and the best checkpoint would fall between validations.
  int val_every = -1;
  size_t val_windows = 64;    // held-out windows scored at each validation
  // Copy calibration in the recipe (world/calibrate.h): at each validation world.copy_bias is fitted on the held-out
  // windows, cross-fitted in two halves (bits_per_token; bits_per_token_uncalibrated beside it), and the weights
  // written (latest, best, final) carry it. Training itself runs with the config's copy_bias.
  bool calibrate = true;
  int stop_after = -1;        // stop (with a checkpoint) after this many steps of this run
  // Train only the parameters whose names start with one of these (e.g. "curvature_mlp"); empty = all. The rest
  // stay as --init gave them: a fine-tune of the action embedding leaves text-only and unconditional outputs as
  // they were.
  std::vector<std::string> train_only;
  // Learning without forgetting (world/distill.h): every example that is not action-conditioned adds
  // distill_weight x KL(these weights' prediction || the model's) per image token, so a fine-tune for action
  // control keeps the text-conditioned and unconditional predictions that text guidance mixes. Empty = off.
  // A teacher trained on words may teach a model that reads embeddings (a fine-tune to another text encoder):
  // it reads its own words of the same captions.
  fs::path distill_from;
  double distill_weight = 1.0;
  // Also hold the text-conditioned prediction under another example's caption (WorldBatch::with_rolled_text, half
  // the batch) to the teacher's: the prompt then may contradict the frames, which is where text guidance works and
  // where no drive of the data shows what should happen (the weather does not change within a drive).
  bool distill_other_text = false;
  // Distil only on windows of procedural drives: a teacher that has never seen recorded footage keeps what it
  // knows of the procedural world and holds real frames to nothing (a fine-tune that adds real drives).
  bool distill_procedural_only = false;
  // Data-parallel ranks, gradient accumulation, sharded optimiser state. Rank 0 alone writes OUT, validates and
  // reports (on_step, on_note).
  train::Parallel parallel;
};

struct WorldStepLog {
  int step = 0, total = 0;
  double lr = 0, loss = 0, grad_norm = 0, tokens_per_s = 0;
  double distill = -1;        // the KL term (nats per image token) when distilling, else -1
  double distill_other = -1;  // the KL term under other examples' captions (distill_other_text), else -1
  bool validation = false;
  nlohmann::json val;         // {"action": nats, "text": nats, "uncond": nats, "bits_action": ...}
};

struct WorldTrainResult {
  int final_step = 0;
  bool resumed = false;
  nlohmann::json last_val;
  int best_step = -1;       // the validation with the lowest bits/token (OUT/best.safetensors); -1 = none
  double best_bits = 0;
  std::vector<std::string> notes;
  // Rank 0 of a fresh run without a teacher: resident memory at its peak above the start of training, and what
  // gaia plan predicts for it (sizing::world_train_memory, beyond the weights); 0 otherwise.
  double peak_memory_beyond_start = 0, planned_memory_beyond_weights = 0;
};

WorldTrainResult train_world(const Config& config, const WorldTrainOptions& opt,
                             const std::function<void(const WorldStepLog&)>& on_step = {},
                             const std::function<void(const std::string&)>& on_note = {});

}  // namespace gaia::world
