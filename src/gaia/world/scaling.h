#pragma once
// `gaia scaling` (§6): a family of world models from a few thousand to a few million parameters, width and depth by
// the rule in the config (world.scaling_*), each trained on the same tokens for its own compute-matched length;
// the law f(x) = c + (x / a)^b (eval/scaling_fit.h) fitted to the final validation losses of all but the largest,
// the largest predicted (and the prediction written down) before it is trained, then trained and compared.
//
//   OUT/runs/<name>/        each model's training run (resumable); <name> = w<d_model>-l<n_layers>
//   OUT/runs/<name>/run.json  its outcome once finished: the run is skipped when OUT is run again
//   OUT/prediction.json     the fit and the largest model's predicted loss, written before it trains
//   OUT/scaling.json        every run, the fit, prediction against outcome; OUT/scaling.svg the plot
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gaia/config.h"
#include "gaia/eval/scaling_fit.h"
#include "gaia/world/token_file.h"

namespace gaia::world {

struct ScalingRun {
  std::string name;
  int d_model = 0, n_layers = 0, n_heads = 0;
  int64_t params = 0;       // N, non-embedding (Kaplan et al.; gaia plan's count)
  int steps = 0;
  double tokens = 0;        // trained on: steps x batch x T x (m + n + l)
  double flops = 0;         // C = 6 N tokens (§6)
  double loss = 0;          // final validation cross-entropy, nats per image token (action-conditioned)
  bool done = false;
};

// The family of `sizes` models for this config and n image tokens a step (no training).
std::vector<ScalingRun> scaling_family(const Config& c, int sizes, int64_t n);
// The config of one member: the architecture and schedule of `run` on top of `c`.
Config scaling_config(const Config& c, const ScalingRun& run);

struct ScalingOptions {
  fs::path tokens, out;
  TokenFormat format;
  int sizes = 5;            // >= 4: the fit needs 3 runs besides the largest
  size_t val_windows = 64;  // held-out windows of each final validation
};

struct ScalingResult {
  std::vector<ScalingRun> runs;   // smallest first; the last is the held-out largest
  eval::PowerLaw fit;             // on all runs but the last
  double predicted = 0;           // the fit at the largest run's compute
  eval::Band band;                // 5-95% of that prediction (residual bootstrap)
  double relative_error = 0;      // (outcome - prediction) / outcome
  nlohmann::json to_json() const;
};

// Trains what is not yet trained (each run resumable), fits, predicts, trains the largest, writes OUT. `on_run`
// hears each run as it starts (index, run); `on_step` and `on_note` as world train's.
ScalingResult run_scaling(const Config& c, const ScalingOptions& o,
                          const std::function<void(size_t, const ScalingRun&)>& on_run = {},
                          const std::function<void(int step, int total)>& on_step = {},
                          const std::function<void(const std::string&)>& on_note = {});

}  // namespace gaia::world
