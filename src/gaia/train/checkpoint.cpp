#include "gaia/train/checkpoint.h"

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
    torch::serialize::OutputArchive ar;
    o->save(ar);
    ar.save_to((stage.path() / (name + ".optim.pt")).string());
  }
  nlohmann::json j = {{"step", state.step}, {"extra", state.extra}};
  write_file_atomic(stage.path() / "state.json", j.dump(2) + "\n");
  stage.commit(/*overwrite=*/true);
}

bool has_checkpoint(const fs::path& dir) { return fs::exists(dir / "state.json"); }

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

void init_from(torch::nn::Module& dst, const torch::nn::Module& src, const fs::path& from,
               const std::function<bool(const std::string&)>& fresh) {
  const auto have = src.named_parameters();
  torch::NoGradGuard ng;
  for (auto& p : dst.named_parameters()) {
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
}

}  // namespace gaia::train
