#include "gaia/world/generate.h"

#include <cmath>
#include <limits>

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/sizing/sizing.h"
#include "gaia/world/batch.h"
#include "gaia/world/prompt_text.h"

namespace gaia::world {

double steer_curvature(const std::string& s) {
  if (s == "left") return 0.01;
  if (s == "right") return -0.01;
  if (s == "strong-left") return 0.033;
  if (s == "strong-right") return -0.033;
  if (s == "straight") return 0.0;
  fail("steer: unknown preset '{}' (choose left, right, strong-left, strong-right, straight or none)", s);
}

torch::Tensor steer_actions(const std::string& preset, double speed, const torch::Tensor& prompt_actions,
                            int64_t frames) {
  double v = speed;
  if (v < 0) {
    v = kDefaultCommandSpeed;
    const int64_t P = prompt_actions.defined() ? prompt_actions.size(0) : 0;
    if (P > 0 && !std::isnan(prompt_actions[P - 1][0].item<float>())) v = prompt_actions[P - 1][0].item<float>();
  }
  const double c = preset != "none" ? steer_curvature(preset) : 0.0;
  return torch::stack({torch::full({frames}, v), torch::full({frames}, c)}, 1).to(torch::kFloat);
}

RolloutOptions default_options(const WorldInfo& info) {
  RolloutOptions o;
  o.sampling.top_k = info.config.world.top_k;
  o.sampling.temperature = info.config.world.temperature;
  o.sampling.guide_actions_within_top_k = info.config.world.guide_actions_within_top_k;
  o.guidance.scale = info.config.world.guidance_scale;
  return o;
}

namespace {

// [rows, 2] in m/s and 1/m, float, on the CPU; `what` names the field.
torch::Tensor actions_in(const torch::Tensor& a, int64_t rows, const char* what) {
  if (a.dim() != 2 || a.size(1) != 2 || a.size(0) != rows)
    fail("{}: shape [{}, 2] expected (speed m/s, curvature 1/m a row), got {}", what, rows,
         shape_str(a.sizes().vec()));
  auto f = a.to(torch::kCPU).to(torch::kFloat).contiguous();
  // NaN means "no action"; infinities are never a speed.
  if (f.isinf().any().item<bool>()) fail("{}: holds an infinite value", what);
  return f;
}

}  // namespace

GenerateResult generate(WorldModel& model, const WorldInfo& info, const std::string& weights,
                        const GenerateRequest& r, const std::shared_ptr<text::TextEncoder>& text,
                        const std::function<void(int, int)>& on_frame) {
  const auto& L = model->layout;
  RolloutOptions o = r.options;
  const int64_t F = o.frames;
  if (F < 1) fail("frames must be >= 1");
  if (o.futures < 1) fail("futures must be >= 1");
  RolloutPrompt p;
  int64_t P = 0;
  if (r.prompt_tokens.defined() && r.prompt_tokens.numel() > 0) {  // rollout() checks the shape and the ids
    p.tokens = r.prompt_tokens.to(torch::kCPU).to(torch::kLong).contiguous();
    if (p.tokens.dim() != 2)
      fail("prompt tokens: shape [P, n = {}] expected, got {}", L.n, shape_str(p.tokens.sizes().vec()));
    P = p.tokens.size(0);
  }
  const int64_t steps = P + F;

  // Actions: the prompt's recorded ones, then the commands; normalised as the model reads them.
  torch::Tensor acts = torch::full({steps, 2}, std::numeric_limits<float>::quiet_NaN());
  bool any_action = false;
  double last_speed = kDefaultCommandSpeed;
  if (P > 0 && r.prompt_actions.defined()) {
    auto pa = actions_in(r.prompt_actions, P, "prompt actions");
    acts.narrow(0, 0, P).copy_(pa);
    any_action = true;
    if (!std::isnan(pa[P - 1][0].item<float>())) last_speed = pa[P - 1][0].item<float>();
  }
  if (r.actions.defined()) {
    if (info.action_share == 0)
      fail("{}: this world model never saw an action (trained on drives without speed or curvature), so steering, "
           "speed and actions would do nothing; train on drives with signals (or gaia ingest --motion video)",
           weights);
    acts.narrow(0, P, F).copy_(actions_in(r.actions, F, "actions"));
    any_action = true;
  }
  acts.select(1, 0).div_(kSpeedScale);
  acts.select(1, 1).div_(kCurvatureScale);
  if (any_action) p.actions = acts;
  const bool commanded = !std::isnan(acts[P][0].item<float>());  // the generated steps have actions
  if (commanded && r.mirror_negative)  // the counter-command: the other way, the prompt's speed
    p.negative_actions = counter_actions(acts, P, torch::tensor(last_speed));
  if (!r.text.empty() || !r.negative.empty()) {
    if (!text) fail("{}: a text prompt needs the model's text encoder", weights);
    if (!r.text.empty()) set_prompt_text(p, text->encode(r.text, L.m), steps);
    if (!r.negative.empty()) set_prompt_text(p, text->encode(r.negative, L.m), steps, true);
  }
  if (r.text_emb.defined()) p.text_emb = r.text_emb;
  if (r.negative_emb.defined()) p.negative_text_emb = r.negative_emb;
  const bool has_text = p.text_ids.defined() || p.text_emb.defined();

  o.guidance.total_frames = int(F);
  if (o.guidance.active() && !p.actions.defined() && !has_text && !p.negative_text_ids.defined() &&
      !p.negative_text_emb.defined())
    fail("guidance needs something to guide towards: a text, a negative prompt, actions or steering");
  const int passes = o.guidance.active() ? (p.actions.defined() && has_text ? 3 : 2) : 1;
  sizing::check_memory(sizing::rollout_memory_bytes(info.config, o.futures, steps, passes, false),
                       fmt::format("futures = {} over {} steps", o.futures, steps));
  auto out = rollout(model, p, o, on_frame);
  return {out.tokens, acts, P, out.seconds};
}

}  // namespace gaia::world
