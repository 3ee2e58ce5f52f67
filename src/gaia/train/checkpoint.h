#pragma once
// Resumable training state: model weights (safetensors), optimiser state, step and a JSON record, saved together
// into a directory that is swapped in atomically. Data order and noise are functions of (seed, step), so a resumed
// run continues exactly as the uninterrupted one would have.
#include <functional>
#include <string>

#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include "gaia/core/fs.h"
#include "gaia/train/distributed.h"

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

// After a kill: if DIR is missing or incomplete but a complete copy of it survives beside it (a save's staging
// directory, or the previous checkpoint moved aside), puts the newest one back as DIR. Then removes the leftovers of
// dead runs. Returns what it did in a line ("" if nothing). Call it holding the run directory's lock (RunDir).
std::string recover_checkpoint(const fs::path& dir);

// Claims a training run's output directory for the life of the object: a lock (a second run on the same --out fails
// at once, naming the first) and then recover_checkpoint(out/checkpoint), whose line goes to `note`.
class RunDir {
 public:
  RunDir(const fs::path& out, const std::function<void(const std::string&)>& note);
  fs::path checkpoint() const { return out_ / "checkpoint"; }

 private:
  fs::path out_;
  DirLock lock_;
};

// A data-parallel run's directory: rank 0 claims it (RunDir) before any rank reads it, the others wait; nullptr on
// the other ranks.
std::unique_ptr<RunDir> claim_run_dir(const fs::path& out, Distributed& dist,
                                      const std::function<void(const std::string&)>& note);

// Loads what save_checkpoint wrote into the same modules / optimisers; returns the state.
CheckpointState load_checkpoint(const fs::path& dir, const std::vector<std::pair<std::string, torch::nn::Module*>>& modules,
                                const std::vector<std::pair<std::string, torch::optim::Optimizer*>>& optimizers);

// Fine-tuning (`--init WEIGHTS`): copies every parameter of `src` into `dst` by name. Parameters of `dst` for
// which `fresh(name)` is true may be absent from `src` (they are trained from scratch); any other absent name or a
// shape mismatch fails naming `from` (the --init file has a different architecture). Parameters for which
// `keep(name)` is true keep their own initialisation whatever `src` has (a part learned afresh). Returns a note
// naming what `src` has and `dst` lacks (dropped: the run's config leaves them out), or "" when nothing is dropped.
std::string init_from(torch::nn::Module& dst, const torch::nn::Module& src, const fs::path& from,
                      const std::function<bool(const std::string&)>& fresh = {},
                      const std::function<bool(const std::string&)>& keep = {});

// Per-step seeding: the same (seed, step) gives the same batch and noise whether or not the run was resumed.
uint64_t step_seed(uint64_t seed, int step, uint64_t stream = 0);

}  // namespace gaia::train
