#pragma once
// The end of a training step, the same for the tokenizer, world model and video decoder trainers: append the step's
// record to metrics.jsonl (flushed, so a killed run keeps its curve), checkpoint when due, and say whether this run
// stops here (--stop-after, or the last step). A resumed run first drops the records after its checkpoint's step
// (the steps an interrupted run did past its last checkpoint are done again), so the curve has each step once.
#include <fstream>
#include <functional>

#include <nlohmann/json.hpp>

#include "gaia/core/fs.h"

namespace gaia::train {

class StepLoop {
 public:
  // start_step: the step the run starts (or resumes) from; records of later steps are removed from the file. An
  // empty path writes no records (the ranks of a data-parallel job other than rank 0).
  StepLoop(const fs::path& metrics_jsonl, int start_step, int total, int checkpoint_every, int stop_after);
  bool validate_now(int step, int val_every) const { return (val_every > 0 && step % val_every == 0) || step == total_; }
  // After step `step` (1-based count of finished steps): logs, saves if due; true = stop this run.
  bool end_step(int step, const nlohmann::json& record, const std::function<void()>& save);

 private:
  std::ofstream metrics_;
  int total_, checkpoint_every_, stop_after_, steps_this_run_ = 0;
};

}  // namespace gaia::train
