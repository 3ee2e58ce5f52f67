#pragma once
// Copy calibration of a trained world model (config world.copy_bias): one logit added to "the same code as one
// frame earlier at this position", fitted by maximum likelihood on training windows. A small, briefly trained model
// spreads too much probability away from that code, so its rollouts change more tokens per frame than real video
// does; a fitted scalar moves the probability of "unchanged" to where the data has it, leaving every other code's
// odds against each other as they were (cf. temperature scaling, Guo et al. 2017).
#include <functional>
#include <vector>

#include <torch/torch.h>

#include "gaia/world/model.h"
#include "gaia/world/token_dataset.h"

namespace gaia::world {

// The maximum-likelihood bias b for events "the token was copied" given each event's probability under b = 0:
// log_p_copy [N] = log p0(copy), copied [N] in {0, 1}. With b the probability becomes
// p_b = p0 e^b / (1 - p0 + p0 e^b); the likelihood is concave in b and its optimum has sum p_b = sum copied.
// Fails if nothing or everything was copied (no finite optimum).
double fit_copy_bias(const torch::Tensor& log_p_copy, const torch::Tensor& copied);

// The same for two kinds of slot (CopyBias): run [N] bool marks the slots whose slot before kept its code. Each kind
// is fitted on its own -> {bias of the others, run's bias - that}; where one kind has no finite optimum, one bias
// for all and run = 0.
CopyBias fit_copy_biases(const torch::Tensor& log_p_copy, const torch::Tensor& copied, const torch::Tensor& run);

struct CopyCalibration {
  bool fitted = true;                // false where no token or every token was copied: no finite optimum, bias kept
  double bias = 0;                   // fitted world.copy_bias (the model's own where not fitted)
  double run = 0;                    // fitted world.copy_bias_run: slots after a kept code are fitted on their own
                                     // (0 where either kind of slot has no finite optimum)
  int64_t tokens = 0;                // image tokens with a previous frame in view, over all windows
  double copy_rate = 0;              // fraction of them equal to the previous frame's code (the data)
  double predicted_before = 0;       // mean probability the model gave that code, with the bias it had
  double predicted_after = 0;        // ... with the fitted bias (= copy_rate at the optimum)
  double nats_before = 0, nats_after = 0;  // mean cross-entropy of those tokens
};

// Teacher-forced logits of `windows` (conditioning drawn with `mix`, as in training), then fit_copy_bias, once for
// the slots whose slot before kept its code and once for the others (CopyBias). The model's own copy bias is the
// starting point, so calibrating twice changes nothing. Steps before a window's scored_from are context only. The
// model is not modified.
CopyCalibration calibrate_copy_bias(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows,
                                    const TextSource& text, const ConditioningMix& mix, int64_t batch,
                                    const std::function<void(int64_t, int64_t)>& progress = {});

}  // namespace gaia::world
