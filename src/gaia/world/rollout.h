#pragma once
// Rolling out futures (§2.3, §5.1): KV-cached incremental decoding of image tokens frame by frame, n forward steps
// per frame, with classifier-free guidance (conditional and unconditional rows in one batch) and a sliding window
// for rollouts longer than the context (drop the oldest step, re-index the temporal positions).
#include <condition_variable>
#include <functional>
#include <future>
#include <memory>
#include <mutex>

#include <torch/torch.h>

#include "gaia/torch/precision.h"
#include "gaia/world/guidance.h"
#include "gaia/world/model.h"
#include "gaia/world/sampling.h"
#include "gaia/world/token_step.h"

namespace gaia::world {

// Every tensor is either shared by all futures (the shapes below) or given per future with a leading [N, ...]
// dimension, so that one batched rollout can run many prompts and commands at once (evaluation does).
struct RolloutPrompt {
  torch::Tensor tokens;             // [P, n] int64 prompt frames (undefined or P = 0: from scratch)
  // Conditioning for every step, prompt and generated (P + F rows each); undefined = none (null tokens).
  torch::Tensor actions;            // [P + F, 2] normalised (batch.h), NaN = no action at that step
  torch::Tensor text_ids;           // [P + F, m] built-in text encoder ids
  torch::Tensor text_emb;           // [P + F, m, text_dim] precomputed text embeddings
  // Negative actions: the unconditional branch sees these actions instead of null ones (e.g. the mirrored command,
  // so that guidance contrasts a right turn with a left one rather than with no command).
  torch::Tensor negative_actions;   // [P + F, 2]
  // Negative prompt (§5.1): the unconditional branch sees this text instead of the null text.
  torch::Tensor negative_text_ids;  // [P + F, m]
  torch::Tensor negative_text_emb;  // [P + F, m, text_dim]
};

struct RolloutOptions {
  int frames = 8;                   // F frames to generate after the prompt
  int futures = 1;                  // N futures sampled in one batch
  SamplingOptions sampling;
  GuidanceSchedule guidance;        // scale 0: no guidance, a single conditional pass
  uint64_t seed = 0;
  // Steps dropped when the window is full. §2.3 slides by one (every frame sees T - 1 steps of history), which
  // re-encodes the whole kept history after every frame, because every kept step's temporal position changes;
  // stride S re-encodes once every S frames, and frames see T - S to T - 1 steps of history.
  int window_stride = 1;
  // With stride 1 where the fused token step applies (the CPU, a few rows) at one intra-op thread: encode the next
  // window's history on a second thread while a frame samples (RolloutStepper::Lookahead). The tokens are those of
  // the plain path up to float rounding.
  bool lookahead = true;
  // Sampling's per-token path on raw memory (token_step.h, and the choice of each token: token_choice.h) where it
  // applies; false: the general LibTorch path (the reference of tests and benchmarks).
  bool fused_tokens = true;
  // The products' precision (--precision): bf16 runs every step, and the lookahead's re-encoding, under autocast;
  // the fused token step, the cached attention and sampling stay float32; on the CPU the cache is kept as bf16.
  Precision precision = Precision::kFp32;
};

struct RolloutResult {
  torch::Tensor tokens;             // [N, P + F, n] prompt followed by the generated frames
  double seconds = 0;               // wall time of the rollout
};

// The counter-command, as negative actions: `actions` ([S, 2] or [N, S, 2], normalised) from step `from` on with
// the curvature mirrored and, when `kept_speed` (m/s, [] or [N]) is defined, that speed. As
// RolloutPrompt::negative_actions, guidance contrasts a turn with its mirror image and a speed change with keeping
// the speed, instead of either with no command: the contrast doubles and a bias both share cancels. A straight
// command at the kept speed is then not guided.
torch::Tensor counter_actions(const torch::Tensor& actions, int64_t from, const torch::Tensor& kept_speed = {});

// One rollout advanced a step at a time: what rollout() runs, and what a closed-loop session (sim/) steps as its
// actions arrive. Each step's conditioning is read from a RolloutPrompt whose per-step rows cover that step (they
// may grow between steps); step k's frame is either given (a prompt frame) or sampled.
class RolloutStepper {
 public:
  RolloutStepper(WorldModel& model, const RolloutOptions& o, int64_t futures);
  // Step k = steps(): encodes `given` ([N, n] or [n]-rows to repeat: a prompt frame) or samples the frame, and
  // returns its tokens [N, n] (on the model's device). `cond`'s rows must cover steps 0..k.
  torch::Tensor step(const RolloutPrompt& cond, const torch::Tensor& given = {});
  int64_t steps() const { return k_; }
  int64_t generated() const { return generated_; }
  torch::Tensor tokens() const;        // [N, steps(), n] every step so far
  RolloutStepper fork() const;         // an independent copy: the same state, cache and random stream
  // A planner's branches, batched: a stepper of `futures` rows that each continue this one-future stepper's state
  // (its cache rows repeated), drawing from one copy of its random stream. With one row it is fork().
  RolloutStepper repeat(int64_t futures) const;
  // Future `i` alone, as a one-future stepper of its own (a copy of the random stream).
  RolloutStepper select(int64_t i) const;

 private:
  WorldModel& model_;
  RolloutOptions o_;
  int64_t N_;
  bool guided_;
  torch::Device dev_;
  at::Generator gen_;
  KVCache cache_;
  std::shared_ptr<const TokenStep> fast_;
  KVCache new_cache(int64_t rows) const;  // the cache's dtype follows the precision (rollout.cpp)
  RolloutStepper rows(const std::vector<int64_t>& futures) const;  // repeat() and select(): these futures' rows  // sampling's per-token path where it applies (shared by forks)
  // §2.3's one-step slide re-encodes the T - 1 kept steps after every frame, but T - 2 of them are known a frame
  // ahead and the newest comes token by token: where the fused token step runs at one intra-op thread, a second
  // thread encodes the next window while the frame samples. A copy of the stepper waits for the job; fork() and
  // rows() give it a cache of its own.
  struct Lookahead {
    static constexpr int64_t kChunk = 48;  // image tokens of the newest step encoded at once
    // How many of the newest step's tokens are out: the job waits for each chunk.
    struct Progress {
      explicit Progress(int64_t n) : total(n) {}
      bool wait_for(int64_t tokens);  // false: abandoned
      void release(int64_t tokens);
      void abandon();
      bool done();
      std::mutex m;
      std::condition_variable cv;
      int64_t sampled = 0, total;
      bool abandoned = false;
    };
    std::shared_future<void> job;
    KVCache cache;        // steps first .. first + T - 2 at temporal positions 0 .. T - 2 once the job is done
    int64_t first = -1;   // -1: nothing ahead
    Lookahead() = default;
    Lookahead(Lookahead&&) = default;
    Lookahead& operator=(Lookahead&&) = default;
    Lookahead(const Lookahead& o);
    Lookahead& operator=(const Lookahead& o);
  };
  Lookahead ahead_;
  torch::Tensor tokens_;  // [B, capacity, n], B = 2N with guidance (the unconditional rows copy the conditional)
  int64_t k_ = 0, generated_ = 0;
  int64_t win_ = 0;       // steps in the cache; the current step sits at temporal position `win_`
};

RolloutResult rollout(WorldModel& model, const RolloutPrompt& prompt, const RolloutOptions& o,
                      const std::function<void(int generated, int total)>& on_frame = {});

}  // namespace gaia::world
