#pragma once
// One training or prompting batch of the world model (§2.1): T steps, each with text c_t, image tokens z_t and
// actions a_t. Conditioning that is absent or dropped (§4.2 conditioning modes) is replaced by learned null tokens
// inside the model, selected here by masks.
#include <torch/torch.h>

namespace gaia::world {

// Actions are fed as scalars of order 1: speed / kSpeedScale and curvature / kCurvatureScale.
// Why these values: city driving in the data is 0-20 m/s and curvature mostly within +-0.02 1/m (50 m radius);
// dividing by them keeps both inputs of the linear action layers in about [-1, 1].
inline constexpr double kSpeedScale = 10.0;       // m/s
inline constexpr double kCurvatureScale = 0.02;   // 1/m; + = left (the synth convention)

struct WorldBatch {
  torch::Tensor tokens;      // [B, T, n] int64 image tokens z in [0, K)
  torch::Tensor actions;     // [B, T, 2] float32, normalised (speed, curvature); NaN = missing -> null action token
  torch::Tensor text_ids;    // [B, T, m] int64 word ids of the built-in text encoder (0 = padding), or undefined
  torch::Tensor text_emb;    // [B, T, m, text_dim] float32 precomputed text embeddings (e.g. T5), or undefined
  torch::Tensor use_action;  // [B] bool: false -> null action tokens for the whole example (undefined = all true)
  torch::Tensor use_text;    // [B] bool: false -> null text tokens (undefined = all true)
  // [B] bool: the window is of a drive gaia synth rendered (or its mirror or replay) under conditions that hold
  // throughout: what --distill-procedural-only holds to the teacher
  torch::Tensor procedural;

  int64_t batch() const { return tokens.size(0); }
  int64_t steps() const { return tokens.size(1); }
  WorldBatch to(const torch::Device& d) const;
  // Steps [t0, t1) of every per-step field (tokens, actions, text); the per-example masks are kept whole, and
  // undefined fields stay undefined. The slices are views (no copy).
  WorldBatch slice_steps(int64_t t0, int64_t t1) const;
  // Examples [b0, b1) of every field (views): a rank's or a micro-batch's share of a step's batch.
  WorldBatch examples(int64_t b0, int64_t b1) const;
  // The first n examples, each given the text of the example after it (the last one the first one's), with text on
  // and actions off: text prompts that may contradict the frames, as text prompting at inference does (§5.1).
  // Needs text (ids or embeddings) and 1 <= n <= batch().
  WorldBatch with_rolled_text(int64_t n) const;
};

}  // namespace gaia::world
