#include "gaia/world/batch.h"

#include "gaia/core/error.h"

namespace gaia::world {

namespace {
torch::Tensor to_device(const torch::Tensor& t, const torch::Device& d) { return t.defined() ? t.to(d) : t; }
torch::Tensor steps_of(const torch::Tensor& t, int64_t t0, int64_t t1) { return t.defined() ? t.slice(1, t0, t1) : t; }
}  // namespace

WorldBatch WorldBatch::to(const torch::Device& d) const {
  return WorldBatch{to_device(tokens, d),     to_device(actions, d),    to_device(text_ids, d),
                    to_device(text_emb, d),   to_device(use_action, d), to_device(use_text, d)};
}

WorldBatch WorldBatch::slice_steps(int64_t t0, int64_t t1) const {
  if (!(0 <= t0 && t0 < t1 && t1 <= steps()))
    fail("slice_steps: [{}, {}) is not a range of the batch's {} steps", t0, t1, steps());
  return WorldBatch{steps_of(tokens, t0, t1), steps_of(actions, t0, t1), steps_of(text_ids, t0, t1),
                    steps_of(text_emb, t0, t1), use_action, use_text};
}

}  // namespace gaia::world
