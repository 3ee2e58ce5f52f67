#include "gaia/world/batch.h"

#include "gaia/core/error.h"

namespace gaia::world {

namespace {
torch::Tensor to_device(const torch::Tensor& t, const torch::Device& d) { return t.defined() ? t.to(d) : t; }
torch::Tensor steps_of(const torch::Tensor& t, int64_t t0, int64_t t1) { return t.defined() ? t.slice(1, t0, t1) : t; }
}  // namespace

WorldBatch WorldBatch::to(const torch::Device& d) const {
  return WorldBatch{to_device(tokens, d),     to_device(actions, d),    to_device(text_ids, d),
                    to_device(text_emb, d),   to_device(use_action, d), to_device(use_text, d),
                    to_device(procedural, d)};
}

WorldBatch WorldBatch::slice_steps(int64_t t0, int64_t t1) const {
  if (!(0 <= t0 && t0 < t1 && t1 <= steps()))
    fail("slice_steps: [{}, {}) is not a range of the batch's {} steps", t0, t1, steps());
  return WorldBatch{steps_of(tokens, t0, t1), steps_of(actions, t0, t1), steps_of(text_ids, t0, t1),
                    steps_of(text_emb, t0, t1), use_action, use_text, procedural};
}

WorldBatch WorldBatch::examples(int64_t b0, int64_t b1) const {
  if (!(0 <= b0 && b0 < b1 && b1 <= batch()))
    fail("examples: [{}, {}) is not a range of the batch's {} examples", b0, b1, batch());
  auto part = [&](const torch::Tensor& t) { return t.defined() ? t.slice(0, b0, b1) : t; };
  return WorldBatch{part(tokens), part(actions), part(text_ids), part(text_emb), part(use_action), part(use_text),
                    part(procedural)};
}

WorldBatch WorldBatch::with_rolled_text(int64_t n) const {
  if (!text_ids.defined() && !text_emb.defined()) fail("with_rolled_text: the batch has no text");
  if (!(1 <= n && n <= batch())) fail("with_rolled_text: {} examples asked of a batch of {}", n, batch());
  auto rolled = [&](const torch::Tensor& t) { return t.defined() ? t.roll(-1, 0).slice(0, 0, n) : t; };
  auto first = [&](const torch::Tensor& t) { return t.slice(0, 0, n); };
  auto opts = torch::TensorOptions().dtype(torch::kBool).device(tokens.device());
  return WorldBatch{first(tokens), first(actions), rolled(text_ids), rolled(text_emb), torch::zeros({n}, opts),
                    torch::ones({n}, opts), procedural.defined() ? first(procedural) : procedural};
}

}  // namespace gaia::world
