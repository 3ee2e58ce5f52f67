#pragma once
// Scoring the world model on held-out windows: cross-entropy of the image tokens (nats; bits/token = nats / ln 2)
// in one conditioning mode, optionally with the conditioning shuffled across examples (does the model use it?),
// and per position within the frame (the paper's Fig. 5).
#include <vector>

#include <optional>

#include "gaia/world/io.h"
#include "gaia/world/model.h"
#include "gaia/world/sampling.h"
#include "gaia/world/token_dataset.h"

namespace gaia::world {

// Windows [b0, b0 + batch) of `windows` -> their batch, with the conditioning mode drawn from rng(b0) (fixed, so a
// window is conditioned the same way in every call).
WorldBatch batch_at(const TokenDataset& ds, const std::vector<Window>& windows, size_t b0, int64_t batch,
                    const TextSource& text, int64_t m, const ConditioningMix& mix);

// How the model reads the dataset's text: its built-in words (when the dataset has captions), or the dataset's
// embeddings, which must come from the encoder the model was trained with (errors name both).
TextSource text_source(const WorldInfo& info, const TokenDataset& ds);

struct ScoreOptions {
  Conditioning mode = Conditioning::kAction;
  bool shuffle = false;    // conditioning of window i taken from window perm(i), a fixed derangement
  int64_t batch = 8;
};

struct Score {
  double nats = 0;                    // mean cross-entropy per image token
  double bits() const;                // nats / ln 2
  std::vector<double> by_position;    // [n] mean cross-entropy of the i-th token of a frame
  int64_t tokens = 0;                 // image tokens scored
};

Score score(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows, const TextSource& text,
            const ScoreOptions& o);

// One token sequence scored as score() scores a dataset's windows: tokens [S, n] in windows of the context's T
// steps, one after another (the last one shorter where T does not divide S), action-conditioned on `actions`
// ([S, 2] speed m/s and curvature 1/m, NaN unknown; undefined: none). Errors name the field at fault.
Score score_tokens(WorldModel& model, const WorldInfo& info, const torch::Tensor& tokens,
                   const torch::Tensor& actions = {}, int64_t batch = 8);

// Fig. 5: what a sampling strategy generates, scored like real tokens. The last frame of each window is generated
// (`sampling`) from the window's T - 1 real frames before it, with its actions, and then scored by teacher forcing
// with the same conditioning, so its per-position cross-entropy is what the model thought of its own draws; with
// `sampling` unset the window's real last frame is scored the same way (the reference the strategies are held
// against: §5.1 chooses k so that generated tokens look like real ones to the model). Also the copy rate of that
// frame: the fraction of its tokens equal to the frame before at the same position.
struct LastFrameScore {
  std::vector<double> by_position;  // [n] mean cross-entropy (nats) of the i-th token of the last frame
  double nats = 0;                  // their mean
  double copy_rate = 0;
};
LastFrameScore score_last_frame(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows,
                                const std::optional<SamplingOptions>& sampling, int64_t batch, uint64_t seed);

// Does the model use the curvature actions, and as much for right turns as for left ones? The rise of the
// image tokens' cross-entropy (nats per token) when every curvature action of the windows is set to 0 or mirrored
// (-c), over the frames that follow a step turning left (curvature > threshold, 1/m), right (< -threshold) or
// neither. Frames after a missing action are left out.
struct SteeringSensitivity {
  struct Row {
    int64_t frames = 0;
    double nats = 0, zeroed_rise = 0, mirrored_rise = 0;
  };
  Row left, right, straight;
};
SteeringSensitivity steering_sensitivity(WorldModel& model, const TokenDataset& ds, const std::vector<Window>& windows,
                                         int64_t batch, double threshold = 0.004);

// [B, T - from, 1] bool: which of steps from, ..., T - 1 of windows [w0, w0 + B) are scored (Window::scored_from).
torch::Tensor scored_steps(const std::vector<Window>& windows, size_t w0, int64_t B, int64_t T, int64_t from = 0);

// Windows that score each frame of the given episodes once, as a compressor reads a stream: the first window of an
// episode scores all its T steps, each later one starts T/2 steps on and scores its last T/2, so each frame after
// the first window has at least T/2 frames before it in view (non-overlapping windows give frame 0 of each none). At
// most `max_windows`: then whole episodes, evenly spaced, each a contiguous run of windows from its middle, so that a
// compressor given the same frames in order sees what the model sees.
std::vector<Window> stream_windows(const TokenDataset& ds, const std::vector<size_t>& episodes, int64_t T,
                                   size_t max_windows);

// Evenly spaced windows of `T` steps from the given episodes, at most `max_windows` (fixed, for validation).
std::vector<Window> validation_windows(const TokenDataset& ds, const std::vector<size_t>& episodes, int64_t T,
                                       size_t max_windows);

}  // namespace gaia::world
