#pragma once
// What `gaia generate` rolls out, as one call (§2.3, §5.1): a video prompt with its recorded actions, commands for
// the generated frames, text and a negative prompt, the counter-command as guidance's negative, the sampling and
// guidance options with the weights' defaults. The CLI and the Python module both call it, so the same request
// and seed give the same tokens from either.
#include <functional>
#include <memory>
#include <string>

#include <torch/torch.h>

#include "gaia/text/encoder.h"
#include "gaia/world/io.h"
#include "gaia/world/rollout.h"

namespace gaia::world {

// Steering presets (curvature in 1/m, + = left): left / right (~100 m radius), strong-left / strong-right (~30 m),
// straight. Anything else fails naming the preset.
double steer_curvature(const std::string& preset);
inline constexpr double kDefaultCommandSpeed = 8.0;  // m/s when neither a command nor the prompt gives a speed
// Commands for `frames` generated frames [frames, 2]: the preset's curvature ("none": 0) at `speed` m/s, or, with
// speed < 0, at the prompt's last recorded speed ([P, 2], NaN unknown; undefined: none) or kDefaultCommandSpeed.
torch::Tensor steer_actions(const std::string& preset, double speed, const torch::Tensor& prompt_actions,
                            int64_t frames);

// The weights' sampling defaults (world.top_k, world.temperature, world.guidance_scale, ...) as rollout options.
RolloutOptions default_options(const WorldInfo& info);

struct GenerateRequest {
  torch::Tensor prompt_tokens;   // [P, n] int64 video prompt (undefined or P = 0: from nothing)
  torch::Tensor prompt_actions;  // [P, 2] the prompt's recorded speed (m/s) and curvature (1/m), NaN unknown
  torch::Tensor actions;         // [F, 2] a command per generated frame, m/s and 1/m; undefined = none
  std::string text, negative;    // text prompt and negative prompt for every step ("" = none)
  torch::Tensor text_emb, negative_emb;  // ... or as embeddings [P + F, m, dim] (read_prompt_embeddings)
  bool mirror_negative = true;   // guidance contrasts the command with the counter-command (false: no actions)
  RolloutOptions options;        // frames F, futures, sampling, guidance (total_frames is set to F), seed
};

struct GenerateResult {
  torch::Tensor tokens;   // [futures, P + F, n] int64, prompt first
  torch::Tensor actions;  // [P + F, 2] every step's conditioning, normalised (batch.h), NaN = none
  int64_t prompt_frames = 0;
  double seconds = 0;
};

// Checks the request against the model (token count, ids, shapes, an action for a model that never saw one,
// guidance with nothing to guide towards, memory) with one line naming `weights` or the field, then rolls out.
// `text` encodes `text` / `negative` (world::prompt_encoder); it may be null when neither is given.
GenerateResult generate(WorldModel& model, const WorldInfo& info, const std::string& weights,
                        const GenerateRequest& request, const std::shared_ptr<text::TextEncoder>& text = {},
                        const std::function<void(int generated, int total)>& on_frame = {});

}  // namespace gaia::world
