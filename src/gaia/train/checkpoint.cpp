#include "gaia/train/checkpoint.h"

#include <sstream>

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::train {

void save_checkpoint(const fs::path& dir, const std::vector<std::pair<std::string, const torch::nn::Module*>>& modules,
                     const std::vector<std::pair<std::string, torch::optim::Optimizer*>>& optimizers,
                     const CheckpointState& state) {
  StagingDir stage(dir);
  for (auto& [name, m] : modules) save_module(*m, stage.path() / (name + ".safetensors"));
  for (auto& [name, o] : optimizers) {
    // Serialised in memory, written by write_file_atomic: LibTorch's file writer throws again from its destructor
    // when the disk fills, which ends the process instead of giving an error line.
    torch::serialize::OutputArchive ar;
    o->save(ar);
    std::ostringstream bytes;
    ar.save_to(bytes);
    write_file_atomic(stage.path() / (name + ".optim.pt"), bytes.str());
  }
  nlohmann::json j = {{"step", state.step}, {"extra", state.extra}};
  write_file_atomic(stage.path() / "state.json", j.dump(2) + "\n");
  stage.commit(/*overwrite=*/true);
}

bool has_checkpoint(const fs::path& dir) { return fs::exists(dir / "state.json"); }

namespace {
int saved_step(const fs::path& dir) {
  try {
    return read_json(dir / "state.json").value("step", -1);
  } catch (const std::exception&) {
    return -1;  // unreadable: not a candidate
  }
}
}  // namespace

std::string recover_checkpoint(const fs::path& dir) {
  const fs::path parent = dir.has_parent_path() ? dir.parent_path() : fs::path(".");
  const std::string name = dir.filename().string();
  std::string said;
  if (!has_checkpoint(dir) && fs::is_directory(parent)) {
    // Copies a kill can leave: StagingDir's ".tmp-NAME-PID-N" (complete once state.json, written last, is there)
    // and "NAME.old-PID-N", the previous checkpoint moved aside.
    fs::path best;
    int best_step = -1;
    for (auto& e : fs::directory_iterator(parent)) {
      const std::string f = e.path().filename().string();
      const bool ours = f.rfind(".tmp-" + name + "-", 0) == 0 || f.rfind(name + ".old-", 0) == 0;
      const long pid = temporary_owner(f);
      if (!ours || pid == 0 || process_alive(pid) || !has_checkpoint(e.path())) continue;
      const int step = saved_step(e.path());
      if (step > best_step) best_step = step, best = e.path();
    }
    if (!best.empty()) {
      std::error_code ec;
      fs::remove_all(dir, ec);
      fs::rename(best, dir);
      said = fmt::format("recovered the checkpoint of step {} from {} (a save was interrupted)", best_step,
                         best.filename().string());
    }
  }
  if (fs::is_directory(parent)) remove_stale_temporaries(parent);
  return said;
}

RunDir::RunDir(const fs::path& out, const std::function<void(const std::string&)>& note) : out_(out), lock_(out) {
  const std::string said = recover_checkpoint(checkpoint());
  if (!said.empty() && note) note(said);
}

CheckpointState load_checkpoint(const fs::path& dir, const std::vector<std::pair<std::string, torch::nn::Module*>>& modules,
                                const std::vector<std::pair<std::string, torch::optim::Optimizer*>>& optimizers) {
  if (!has_checkpoint(dir)) fail("{}: no checkpoint (state.json missing)", dir.string());
  for (auto& [name, m] : modules) load_module(*m, dir / (name + ".safetensors"));
  for (auto& [name, o] : optimizers) {
    fs::path p = dir / (name + ".optim.pt");
    if (!fs::exists(p)) fail("{}: missing", p.string());
    torch::serialize::InputArchive ar;
    try {
      ar.load_from(p.string());
      o->load(ar);
    } catch (const c10::Error& e) {
      fail("{}: corrupt optimiser state ({})", p.string(), e.what_without_backtrace());
    }
  }
  const nlohmann::json j = read_json(dir / "state.json");
  CheckpointState s;
  s.step = j.value("step", 0);
  s.extra = j.value("extra", nlohmann::json::object());
  return s;
}

uint64_t step_seed(uint64_t seed, int step, uint64_t stream) {
  // splitmix64 of the combined key: well-mixed, platform-independent.
  uint64_t z = seed * 0x9E3779B97F4A7C15ull + static_cast<uint64_t>(step) * 0xBF58476D1CE4E5B9ull + stream * 0x94D049BB133111EBull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

std::string init_from(torch::nn::Module& dst, const torch::nn::Module& src, const fs::path& from,
                      const std::function<bool(const std::string&)>& fresh,
                      const std::function<bool(const std::string&)>& keep) {
  const auto have = src.named_parameters();
  const auto want = dst.named_parameters();
  std::vector<std::string> dropped;
  for (const auto& q : have)
    if (!want.find(q.key())) dropped.push_back(q.key());
  torch::NoGradGuard ng;
  for (auto& p : dst.named_parameters()) {
    if (keep && keep(p.key())) continue;
    const auto* q = have.find(p.key());
    if (!q) {
      if (fresh && fresh(p.key())) continue;
      fail("{}: no tensor '{}' (the --init weights have a different architecture)", from.string(), p.key());
    }
    if (!q->sizes().equals(p.value().sizes()))
      fail("{}: '{}' has shape {} but the config needs {}", from.string(), p.key(), shape_str(q->sizes().vec()),
           shape_str(p.value().sizes().vec()));
    p.value().copy_(q->to(p.value().device(), p.value().scalar_type()));
  }
  if (dropped.empty()) return "";
  return fmt::format("{}: {} tensors this run's config has no place for are dropped (first: '{}'); give the config "
                     "the --init weights were trained with to keep them",
                     from.string(), dropped.size(), dropped.front());
}

std::unique_ptr<RunDir> claim_run_dir(const fs::path& out, Distributed& dist,
                                      const std::function<void(const std::string&)>& note) {
  std::unique_ptr<RunDir> run_dir;
  if (dist.is_main()) run_dir = std::make_unique<RunDir>(out, note);
  dist.barrier();
  return run_dir;
}

}  // namespace gaia::train
