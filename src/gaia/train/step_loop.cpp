#include "gaia/train/step_loop.h"

namespace gaia::train {

namespace {

// Keeps the records of steps <= last (and drops a torn last line of a killed run); rewritten atomically.
void truncate_after(const fs::path& file, int last) {
  if (!fs::exists(file)) return;
  std::ifstream in(file);
  std::string line, kept;
  bool dropped = false;
  while (std::getline(in, line)) {
    auto j = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (j.is_object() && j.contains("step") && j["step"].is_number() && j["step"].get<int>() <= last)
      kept += line + "\n";
    else
      dropped = true;
  }
  if (dropped) write_file_atomic(file, kept);
}

}  // namespace

StepLoop::StepLoop(const fs::path& metrics_jsonl, int start_step, int total, int checkpoint_every, int stop_after)
    : total_(total), checkpoint_every_(checkpoint_every), stop_after_(stop_after) {
  if (metrics_jsonl.empty()) return;
  truncate_after(metrics_jsonl, start_step);
  metrics_.open(metrics_jsonl, std::ios::app);
}

bool StepLoop::end_step(int step, const nlohmann::json& record, const std::function<void()>& save) {
  ++steps_this_run_;
  if (metrics_.is_open()) {
    metrics_ << record.dump() << "\n";
    metrics_.flush();
  }
  const bool stop = (stop_after_ > 0 && steps_this_run_ >= stop_after_) || step >= total_;
  if ((checkpoint_every_ > 0 && step % checkpoint_every_ == 0) || stop) save();
  return stop;
}

}  // namespace gaia::train
