#pragma once
// A closed-loop session with the world model (DESIGN.md, "closed loop"): a policy or a person sends an action per
// step and gets the next frame's tokens, made exactly as `gaia generate` makes them (KV cache, sliding window,
// guidance with the counter-command as the negative), so a session stepped with a fixed action sequence and seed
// gives the tokens of `gaia generate` with that sequence and seed. fork() branches a session into an independent
// copy of its whole state (cache, history, random stream): a planner tries several actions from one state.
// Frames are tokens here; decoding them to pixels is the caller's (the tokenizer's decoder), so this stays free of
// video code.
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "gaia/text/encoder.h"
#include "gaia/world/io.h"
#include "gaia/world/rollout.h"

namespace gaia::sim {

struct SessionSettings {
  uint64_t seed = 0;
  double guidance_scale = -1;   // -1: the weights' world.guidance_scale (§5.1 classifier-free guidance)
  std::string sampling = "top-k";
  int top_k = -1;               // -1: the weights' world.top_k
  double temperature = -1;      // -1: the weights' world.temperature
  int window_stride = 1;        // §2.3: slide the window by one step
  bool mirror_negative = true;  // guidance contrasts a command with its mirror image at the prompt's speed
  bool negative_keeps_speed = false;  // ... at the command's own speed instead: guidance on the turn alone
  Precision precision = Precision::kFp32;  // the products' (RolloutOptions::precision): the server's --precision
};

struct Action {
  double speed = std::numeric_limits<double>::quiet_NaN();      // m/s; NaN: no command
  double curvature = std::numeric_limits<double>::quiet_NaN();  // 1/m, + = left
};

inline constexpr double kMaxSpeed = 100;      // m/s
inline constexpr double kMaxCurvature = 0.5;  // 1/m: a 2 m radius
// Fails with one line naming the value unless speed is in [0, kMaxSpeed] and curvature in
// [-kMaxCurvature, kMaxCurvature] (NaN: none).
void check_action(const Action& a);

class SimSession {
 public:
  // `model` outlives the session (sessions of one model share its weights). `text` encodes text prompts
  // (world/prompt_text.h); undefined = the model's own words, and for a model that reads embeddings, no text.
  SimSession(world::WorldModel& model, const world::WorldInfo& info, const SessionSettings& s,
             std::shared_ptr<text::TextEncoder> text = {});

  // The video prompt: `tokens` [P, n] (P may be 0: from nothing), their actions [P, 2] in m/s and 1/m (NaN where
  // unknown; undefined = none) and a text prompt ("" = none). P must leave room for a generated step in the context.
  void start(const torch::Tensor& tokens, const torch::Tensor& actions = {}, const std::string& text = "");
  // The next frame's tokens [n] (int64, CPU) under `a`; `text` replaces the text prompt from this step on.
  torch::Tensor step(const Action& a, const std::optional<std::string>& text = std::nullopt);
  // Back to the state start() left (the same random stream again).
  void reset();
  SimSession fork() const;
  // A planner's candidates: one copy of this session per plan, each stepped along its plan (one action per step,
  // all plans of one length, `text` as in step()); this session is unchanged. Batched, the plans' steps run as one
  // batch of futures, each plan drawing from its own row of one random stream (with one plan: the frames of fork()
  // then step()). One by one, each copy is fork() then step(). Auto batches where the rows share the work: on an
  // accelerator; on the CPU each one-row copy has the fused token step and its lookahead, which a batch of rows
  // does not beat (docs/benchmarks.md).
  enum class Branching { Auto, Batched, OneByOne };
  std::vector<SimSession> fork(const std::vector<std::vector<Action>>& plans,
                               const std::optional<std::string>& text = std::nullopt,
                               Branching how = Branching::Auto) const;
  SimSession(SimSession&&) = default;
  SimSession& operator=(SimSession&&) = default;

  int64_t steps() const { return stepper_ ? stepper_->steps() : 0; }  // prompt frames + generated frames
  int64_t prompt_frames() const { return P_; }
  const std::string& text() const { return text_; }
  torch::Tensor tokens() const;  // [steps, n] every frame so far, prompt first

 private:
  world::WorldModel* model_;
  const world::WorldInfo* info_;
  world::RolloutOptions o_;
  bool mirror_, mirror_keeps_speed_;
  std::shared_ptr<text::TextEncoder> encoder_;
  // Per-step conditioning, one row per step so far (+1 while stepping), as rollout() reads it.
  world::RolloutPrompt cond_;
  torch::Tensor prompt_tokens_, prompt_actions_;  // start()'s arguments, for reset()
  std::string prompt_text_, text_;
  int64_t P_ = 0;
  double kept_speed_ = 8.0;  // m/s: the counter-command's speed (the prompt's last, as gaia generate)
  std::shared_ptr<world::RolloutStepper> stepper_;

  SimSession(const SimSession&) = default;  // shares the stepper: fork() replaces it at once

  void append_row(const Action& a);
  torch::Tensor text_row(const std::string& text) const;  // [m] word ids or [m, dim] embeddings
  torch::Tensor& text_rows();                             // cond_'s text field of that kind
};

}  // namespace gaia::sim
