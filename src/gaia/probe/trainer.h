#pragma once
// `gaia probe train`: the dynamics and scene probes on a procedural-world dataset (frames with ground-truth labels),
// with held-out evaluation on the dataset's validation episodes; resumable like every trainer here.
#include <functional>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "gaia/core/config.h"
#include "gaia/data/episode.h"
#include "gaia/data/frame_set.h"
#include "gaia/probe/probe.h"

namespace gaia::probe {

// BGR frames (1 for scene, 2 for dynamics) -> one probe input [3 * frames, H, W] in [-1, 1].
torch::Tensor probe_input(const std::vector<cv::Mat>& frames);

// One labelled example: frame i of an episode (and frame i + stride for dynamics).
using Example = data::FrameRef;
using ExampleSet = data::FrameSet;
// The native frames between the two inputs of the dynamics probe: one world-model step (25 Hz / 6.25 Hz = 4).
int dynamics_stride(const Config& c);
// Targets of examples: dynamics [N, 2] normalised speed/curvature averaged over the step; scene [N, 4] int64 class
// ids (weather, time, light, lead close). Errors name the episode when a label is missing.
torch::Tensor targets(ProbeKind kind, const std::vector<std::unique_ptr<data::Episode>>& eps,
                      const std::vector<Example>& ex, int stride);
torch::Tensor inputs(ProbeKind kind, const std::vector<std::unique_ptr<data::Episode>>& eps,
                     const std::vector<Example>& ex, int stride);

// Network outputs for a set, in batches (no gradients) -> [N, outputs] on the CPU.
torch::Tensor predict(ProbeNet& net, const ExampleSet& s, int stride, const torch::Device& dev);

// Metrics of predictions against targets: dynamics -> speed / curvature MAE (m/s, 1/m), Spearman, steering sign
// accuracy (|curvature| >= 0.002 1/m); scene -> accuracy of each attribute.
nlohmann::json score(ProbeKind kind, const torch::Tensor& pred, const torch::Tensor& target);

struct ProbeTrainOptions {
  fs::path dataset, out;   // OUT/checkpoint/, OUT/probe-<kind>.safetensors, OUT/metrics.jsonl
  ProbeKind kind = ProbeKind::kScene;
  int steps = 1500, batch = 32, val_every = 250, val_examples = 512, stop_after = -1;
  double lr = 1e-3;
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

// Loading a shipped probe (kind in the metadata).
ProbeNet load_probe(const fs::path& path, const torch::Device& device);

}  // namespace gaia::probe
