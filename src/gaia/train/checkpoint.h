#pragma once
// Resumable training state: model weights (safetensors), optimiser state, step and a JSON record, saved together
// into a directory that is swapped in atomically. Data order and noise are functions of (seed, step), so a resumed
// run continues exactly as the uninterrupted one would have.
#include <functional>
#include <string>

#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include "gaia/core/fs.h"

namespace gaia::train {

struct CheckpointState {
  int step = 0;
  nlohmann::json extra;  // anything the trainer wants back (best validation loss, config name, ...)
};

// Writes DIR/{model.safetensors, optimizer.pt, state.json} (+ any extra modules) via a staging directory.
void save_checkpoint(const fs::path& dir, const std::vector<std::pair<std::string, const torch::nn::Module*>>& modules,
                     const std::vector<std::pair<std::string, torch::optim::Optimizer*>>& optimizers,
                     const CheckpointState& state);

// True if DIR holds a complete checkpoint.
bool has_checkpoint(const fs::path& dir);

// Loads what save_checkpoint wrote into the same modules / optimisers; returns the state.
CheckpointState load_checkpoint(const fs::path& dir, const std::vector<std::pair<std::string, torch::nn::Module*>>& modules,
                                const std::vector<std::pair<std::string, torch::optim::Optimizer*>>& optimizers);

// Fine-tuning (`--init WEIGHTS`): copies every parameter of `src` into `dst` by name. Parameters of `dst` for
// which `fresh(name)` is true may be absent from `src` (they are trained from scratch); any other absent name or a
// shape mismatch fails naming `from` (the --init file has a different architecture).
void init_from(torch::nn::Module& dst, const torch::nn::Module& src, const fs::path& from,
               const std::function<bool(const std::string&)>& fresh = {});

// Per-step seeding: the same (seed, step) gives the same batch and noise whether or not the run was resumed.
uint64_t step_seed(uint64_t seed, int step, uint64_t stream = 0);

}  // namespace gaia::train
