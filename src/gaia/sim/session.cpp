#include "gaia/sim/session.h"

#include "gaia/world/generate.h"

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/core/numbers.h"
#include "gaia/world/batch.h"
#include "gaia/world/prompt_text.h"

namespace gaia::sim {

namespace {

// Appends one row to a per-step tensor [k, ...] (undefined: the row alone).
torch::Tensor append(const torch::Tensor& rows, const torch::Tensor& row) {
  return rows.defined() ? torch::cat({rows, row.unsqueeze(0)}) : row.unsqueeze(0);
}
}  // namespace

SimSession::SimSession(world::WorldModel& model, const world::WorldInfo& info, const SessionSettings& s,
                       std::shared_ptr<text::TextEncoder> text)
    : model_(&model), info_(&info), mirror_(s.mirror_negative), mirror_keeps_speed_(s.negative_keeps_speed), encoder_(std::move(text)) {
  if (!encoder_ && !info.embeds_text()) encoder_ = std::make_shared<text::WordEncoder>(info.vocab);
  o_ = world::default_options(info);  // the weights' sampling, as gaia generate's
  o_.seed = s.seed;
  o_.window_stride = s.window_stride;
  o_.precision = s.precision;
  o_.sampling.strategy = world::parse_strategy(s.sampling);
  if (s.top_k > 0) o_.sampling.top_k = s.top_k;
  if (s.temperature > 0) o_.sampling.temperature = s.temperature;
  if (s.guidance_scale >= 0) o_.guidance.scale = s.guidance_scale;
  if (!(o_.guidance.scale >= 0 && o_.guidance.scale <= 100))
    fail("guidance scale must be in [0, 100], got {}", o_.guidance.scale);
  if (s.window_stride < 1 || s.window_stride >= model->layout.T)
    fail("window stride must be in [1, T - 1 = {}], got {}", model->layout.T - 1, s.window_stride);
}

torch::Tensor SimSession::text_row(const std::string& text) const {
  if (!encoder_)
    fail("this world model reads text as embeddings of {}: text prompts need that encoder (gaia sim --t5 DIR)",
         info_->text_encoder);
  return encoder_->encode(text, (*model_)->layout.m);
}

torch::Tensor& SimSession::text_rows() { return info_->embeds_text() ? cond_.text_emb : cond_.text_ids; }

void SimSession::start(const torch::Tensor& tokens, const torch::Tensor& actions, const std::string& text) {
  const auto& L = (*model_)->layout;
  const int64_t P = tokens.defined() ? tokens.size(0) : 0;
  if (tokens.defined() && P > 0) {
    if (tokens.dim() != 2 || tokens.size(1) != L.n)
      fail("prompt tokens must be [frames, n = {}], got {}", L.n, shape_str(tokens.sizes().vec()));
    const auto lo = tokens.min().item<int64_t>(), hi = tokens.max().item<int64_t>();
    if (lo < 0 || hi >= (*model_)->K) fail("prompt tokens must be in [0, K = {}), found {}..{}", (*model_)->K, lo, hi);
  }
  if (P >= L.T) fail("the prompt has {} frames; the context holds {} steps, so at most {}", P, L.T, L.T - 1);
  if (actions.defined() && (actions.dim() != 2 || actions.size(0) != P || actions.size(1) != 2))
    fail("prompt actions must be [frames = {}, 2] (speed m/s, curvature 1/m), got {}", P, shape_str(actions.sizes().vec()));
  prompt_tokens_ = P > 0 ? tokens.to(torch::kLong).cpu().clone() : torch::Tensor();
  prompt_actions_ = actions.defined() ? actions.to(torch::kFloat).cpu().clone() : torch::Tensor();
  prompt_text_ = text;
  P_ = P;
  reset();
}

void SimSession::reset() {
  cond_ = {};
  text_ = prompt_text_;
  kept_speed_ = 8.0;  // as gaia generate: the prompt's last speed, else 8 m/s
  auto acts = torch::full({P_, 2}, kNaN, torch::kFloat);
  if (prompt_actions_.defined() && P_ > 0) {
    acts.copy_(prompt_actions_);
    acts.select(1, 0).div_(world::kSpeedScale);
    acts.select(1, 1).div_(world::kCurvatureScale);
    const double v = prompt_actions_[P_ - 1][0].item<double>();
    if (!std::isnan(v)) kept_speed_ = v;
  }
  cond_.actions = acts;
  // The counter-command (world::counter_actions) leaves the prompt's own actions as they are.
  if (mirror_) cond_.negative_actions = acts.clone();
  if (!text_.empty()) {
    text_rows() = world::repeat_rows(text_row(text_), P_);
  }
  stepper_ = std::make_shared<world::RolloutStepper>(*model_, o_, 1);
  for (int64_t k = 0; k < P_; ++k) stepper_->step(cond_, prompt_tokens_[k]);
}

void check_action(const Action& a) {
  for (double x : {a.speed, a.curvature})
    if (std::isinf(x)) fail("an action must be finite or NaN (no command), got {}", x);
  if (!std::isnan(a.speed) && (a.speed < 0 || a.speed > kMaxSpeed))
    fail("speed must be in [0, {}] m/s, got {}", kMaxSpeed, a.speed);
  if (!std::isnan(a.curvature) && std::abs(a.curvature) > kMaxCurvature)
    fail("curvature must be in [-{}, {}] 1/m, got {}", kMaxCurvature, kMaxCurvature, a.curvature);
}

void SimSession::append_row(const Action& a) {
  const auto row = torch::tensor({float(a.speed / world::kSpeedScale), float(a.curvature / world::kCurvatureScale)});
  cond_.actions = append(cond_.actions, row);
  if (mirror_) {
    // A command's counter-command: the other way at the prompt's speed; no command contrasts with nothing.
    const bool commanded = !std::isnan(a.speed) || !std::isnan(a.curvature);
    const float v = mirror_keeps_speed_ ? row[0].item<float>() : float(kept_speed_ / world::kSpeedScale);
    auto neg = commanded ? torch::tensor({v, -row[1].item<float>()})
                         : torch::tensor({float(kNaN), float(kNaN)});
    cond_.negative_actions = append(cond_.negative_actions, neg);
  }
  torch::Tensor& rows = text_rows();
  if (!text_.empty() || rows.defined()) {
    // Text given after steps without any: those steps read as the empty caption from now on.
    const int64_t k = cond_.actions.size(0) - 1;
    if (!rows.defined()) rows = world::repeat_rows(text_row(""), k);
    rows = append(rows, text_row(text_));
  }
}

torch::Tensor SimSession::step(const Action& a, const std::optional<std::string>& text) {
  if (!stepper_) fail("a session steps after start()");
  check_action(a);
  if (text && !text->empty()) text_row(*text);  // a text this session cannot encode fails before anything changes
  if (text) text_ = *text;
  append_row(a);
  return stepper_->step(cond_).reshape({-1}).to(torch::kCPU);
}

SimSession SimSession::fork() const {
  SimSession c(*this);
  if (stepper_) c.stepper_ = std::make_shared<world::RolloutStepper>(stepper_->fork());
  return c;  // the conditioning rows are replaced, never written in place, so sharing them is safe
}

std::vector<SimSession> SimSession::fork(const std::vector<std::vector<Action>>& plans,
                                         const std::optional<std::string>& text, Branching how) const {
  if (!stepper_) fail("a session forks after start()");
  if (plans.empty()) fail("fork needs at least one plan");
  const size_t h = plans[0].size();
  for (size_t i = 0; i < plans.size(); ++i) {
    if (plans[i].size() != h) fail("every plan needs the same number of steps (plan 0 has {}, plan {} has {})", h, i, plans[i].size());
    for (const auto& a : plans[i]) check_action(a);
  }
  if (text && !text->empty()) text_row(*text);  // fails before anything is made
  const bool cpu = (*model_)->token_embedding->weight.device().is_cpu();
  std::vector<SimSession> out;
  if (how == Branching::OneByOne || (how == Branching::Auto && cpu)) {
    for (const auto& plan : plans) {
      out.push_back(fork());
      for (const auto& a : plan) out.back().step(a, text);
    }
    return out;
  }
  for (size_t i = 0; i < plans.size(); ++i) {
    out.push_back(SimSession(*this));
    if (text) out.back().text_ = *text;
    for (const auto& a : plans[i]) out.back().append_row(a);
  }
  // Every branch's conditioning as one per-future prompt [plans, steps, ...] (the fields each branch has alike).
  world::RolloutPrompt batch;
  auto stack = [&](torch::Tensor world::RolloutPrompt::*field) {
    if (!(out[0].cond_.*field).defined()) return;
    std::vector<torch::Tensor> rows;
    for (const auto& b : out) rows.push_back(b.cond_.*field);
    batch.*field = torch::stack(rows);
  };
  for (auto f : {&world::RolloutPrompt::actions, &world::RolloutPrompt::negative_actions,
                 &world::RolloutPrompt::text_ids, &world::RolloutPrompt::text_emb})
    stack(f);
  auto steps = stepper_->repeat(int64_t(plans.size()));
  for (size_t j = 0; j < h; ++j) steps.step(batch);
  for (size_t i = 0; i < out.size(); ++i)
    out[i].stepper_ = std::make_shared<world::RolloutStepper>(steps.select(int64_t(i)));
  return out;
}

torch::Tensor SimSession::tokens() const {
  return stepper_ ? stepper_->tokens()[0].to(torch::kCPU) : torch::empty({0, (*model_)->layout.n}, torch::kLong);
}

}  // namespace gaia::sim
