#include "gaia/train/step_loop.h"

namespace gaia::train {

StepLoop::StepLoop(const fs::path& metrics_jsonl, int total, int checkpoint_every, int stop_after)
    : metrics_(metrics_jsonl, std::ios::app), total_(total), checkpoint_every_(checkpoint_every), stop_after_(stop_after) {}

bool StepLoop::end_step(int step, const nlohmann::json& record, const std::function<void()>& save) {
  ++steps_this_run_;
  metrics_ << record.dump() << "\n";
  metrics_.flush();
  const bool stop = (stop_after_ > 0 && steps_this_run_ >= stop_after_) || step >= total_;
  if ((checkpoint_every_ > 0 && step % checkpoint_every_ == 0) || stop) save();
  return stop;
}

}  // namespace gaia::train
