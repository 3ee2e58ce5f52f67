#pragma once
// `gaia probe train`: the dynamics and scene probes on a procedural-world dataset (frames with ground-truth labels;
// recorded footage too, with its signals or its manifest's conditions as the labels), the realism probe on a dataset of real and procedural episodes, with held-out evaluation on the dataset's validation episodes; resumable like every trainer here.
#include <functional>
#include <random>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "gaia/config.h"
#include "gaia/data/episode.h"
#include "gaia/data/frame_set.h"
#include "gaia/probe/probe.h"
#include "gaia/tokenizer/autoencoder.h"

namespace gaia::probe {

// BGR frames (1 for scene, K for dynamics) -> one probe input [3 * frames, H, W] in [-1, 1].
torch::Tensor probe_input(const std::vector<cv::Mat>& frames);

// One labelled example: frame i of an episode (and, for dynamics, frames i + stride, ..., i + (K - 1) stride).
using Example = data::FrameRef;
using ExampleSet = data::FrameSet;
// The native frames between consecutive inputs of the dynamics probe: one world-model step (25 Hz / 6.25 Hz = 4).
int dynamics_stride(const Config& c);
// What one example reads: `frames` frames, `stride` native frames apart (the scene probe: one frame).
struct Span {
  int frames = 1, stride = 0;
  int reach() const { return (frames - 1) * stride; }  // native frames from the first input to the last
};
Span span_of(const ProbeNet& net, const Config& c);
// Targets of examples: dynamics [N, 2] normalised speed/curvature averaged over the span's native frames; scene
// [N, 4] int64 class ids (weather, time, light, lead close); realism [N, 1], 1 for real footage. Errors name the episode when a label is missing.
torch::Tensor targets(ProbeKind kind, const std::vector<std::unique_ptr<data::Episode>>& eps,
                      const std::vector<Example>& ex, const Span& span);
// The dynamics probe's examples whose span has a speed and curvature on every native frame: recorded footage with
// estimated actions has gaps (docs/your-drives.md). Returns how many were left out.
size_t keep_with_signals(ExampleSet& s, const Span& span);
// A horizontal flip of dynamics inputs [N, 3 * frames, H, W] and targets [N, 2] where `flip` is set: the same drive
// in mirror image, turning the other way (tokenize --mirror's rule).
void mirror_dynamics(torch::Tensor& x, torch::Tensor& y, const std::vector<bool>& flip);
// Inputs [N, 3 * frames, H, W] of examples; with `through` (a tokenizer) the examples whose `decoded` flag is set
// (all when `decoded` is empty) are first encoded and decoded by it, the way `gaia eval` reads generated frames.
struct Through {
  tokenizer::ImageTokenizer* tokenizer = nullptr;
  torch::Device device = torch::kCPU;
};
torch::Tensor inputs(const std::vector<std::unique_ptr<data::Episode>>& eps, const std::vector<Example>& ex,
                     const Span& span, const Through& through = {}, const std::vector<bool>& decoded = {});
// The tokenizer for `Through`; fails naming both paths when it reads another frame size than `sample`'s.
tokenizer::ImageTokenizer load_through(const fs::path& tokenizer, const cv::Mat& sample, const fs::path& dataset,
                                       const torch::Device& dev);

// Network outputs for a set, in batches (no gradients) -> [N, outputs] on the CPU; every frame through the
// tokenizer when `through` has one.
torch::Tensor predict(ProbeNet& net, const ExampleSet& s, const Span& span, const torch::Device& dev,
                      const Through& through = {});

// The realism probe's training augmentation of inputs [B, 3, H, W] in [-1, 1]: a random crop (70-100% of each side)
// resized back, a horizontal flip, saturation (grey a quarter of the time), contrast and brightness, per example.
torch::Tensor realism_augment(const torch::Tensor& x, std::mt19937_64& rng);

// Up to n frames of the episodes `ids`, half from real footage and half procedural (every frame when n <= 0), each
// half spread evenly over its episodes: the realism probe's held-out set.
ExampleSet footage_balanced_set(const data::Dataset& ds, const std::vector<std::string>& ids, int n);

// Metrics of predictions against targets: dynamics -> speed / curvature MAE (m/s, 1/m), Spearman, steering sign
// accuracy (|curvature| >= 0.002 1/m), mean curvature error (its bias, 1/m); scene -> accuracy of each attribute; realism -> accuracy and the share of
// real and of procedural frames read as real.
nlohmann::json score(ProbeKind kind, const torch::Tensor& pred, const torch::Tensor& target);

// score() of the whole set, and where it mixes recorded footage with procedural drives, of the recorded frames
// alone ("real"): what a probe that learned both reads on real roads.
nlohmann::json score_by_footage(ProbeKind kind, const torch::Tensor& pred, const torch::Tensor& target,
                                const ExampleSet& s);

struct ProbeTrainOptions {
  fs::path dataset, out;   // OUT/checkpoint/, OUT/probe-<kind>.safetensors, OUT/metrics.jsonl
  ProbeKind kind = ProbeKind::kScene;
  int frames = 0;          // frames an example reads: 0 = kDynamicsFrames for dynamics, 1 for scene
  int steps = 1500, batch = 32, val_every = 250, val_examples = 512, stop_after = -1;
  double lr = 1e-3;
  // A share of each batch read through this tokenizer (encoded, quantised, decoded): generated frames reach the
  // probe through its decoder, and a probe trained on raw frames alone misses cues the decoder redraws (rain
  // streaks, for one). Validation then also scores decoded held-out frames.
  fs::path tokenizer;
  double decoded_share = 0.5;
  // Dynamics: half of each batch in mirror image, curvature negated (a probe that learns left and right alike).
  bool mirror = false;
};

struct ProbeTrainResult {
  int final_step = 0;
  bool resumed = false;
  nlohmann::json last_val;
  fs::path weights;
};

ProbeTrainResult train_probe(const Config& config, const ProbeTrainOptions& opt,
                             const std::function<void(int step, int total, double loss, const nlohmann::json& val)>& on_step = {},
                             const std::function<void(const std::string&)>& on_note = {});

// Loading a shipped probe (kind and frames in the metadata; a dynamics file without frames is a pair probe).
ProbeNet load_probe(const fs::path& path, const torch::Device& device);

}  // namespace gaia::probe
