#pragma once
// Evaluation probes (what the paper shows in pictures, measured): small CNNs trained on procedural-world frames,
// whose read-back of generated video is compared with what was asked for.
//   dynamics  K >= 2 frames 0.16 s apart (steps at 6.25 Hz) -> the ego's mean speed and curvature over them; a
//             longer window sees the heading change and the lateral drift that one step of gentle steering hides
//   scene     one frame -> weather, time of day, traffic-light state, whether a lead vehicle is close
//   realism   one frame -> whether it is real camera footage or the procedural world (trained on a dataset that holds
//             both); the share of generated frames it reads as real says how far rollouts of real prompts stay real
// Their penultimate features give a Frechet distance between sets of clips ("FD-probe"; it is not FVD: the
// features come from our probes trained on our procedural world, not from an I3D network trained on Kinetics).
#include <string>
#include <vector>

#include <torch/torch.h>

namespace gaia::probe {

enum class ProbeKind { kDynamics, kScene, kRealism };
ProbeKind parse_kind(const std::string& s);  // "dynamics" | "scene" | "realism"
std::string to_string(ProbeKind k);

// Class names of the scene attributes (the synth labels' vocabularies).
const std::vector<std::string>& weather_classes();      // clear, overcast, rain, fog, snow
const std::vector<std::string>& time_classes();         // day, dusk, night
const std::vector<std::string>& light_classes();        // none, green, amber, red
int class_index(const std::vector<std::string>& classes, const std::string& name);  // -1 if unknown

// Frames the dynamics probe reads by default: 4 (three world-model steps). Gentle steering barely turns the road
// in one step, so a pair of frames reads a commanded curve less reliably than four. Files saved before the frame
// count was recorded are pair probes.
inline constexpr int64_t kDynamicsFrames = 4;

// x [B, 3 * frames, H, W] in [-1, 1] -> features [B, width] (global average of the last conv block).
// frames: the scene probe reads 1; the dynamics probe K >= 2 (0 = the default: kDynamicsFrames, or 1 for scene).
struct ProbeNetImpl : torch::nn::Module {
  explicit ProbeNetImpl(ProbeKind kind, int64_t frames = 0, int64_t width = 128);
  torch::Tensor features(const torch::Tensor& x);
  // dynamics: [B, 2] normalised (speed / kSpeedScale, curvature / kCurvatureScale);
  // scene: logits concatenated [B, 5 + 3 + 4 + 2] (weather | time | light | lead close); realism: [B, 1], the logit
  // of "real footage".
  torch::Tensor forward(const torch::Tensor& x) { return head(features(x)); }
  int64_t in_frames() const { return frames; }

  ProbeKind kind;
  int64_t frames;
  torch::nn::Sequential body{nullptr};
  torch::nn::Linear head{nullptr};
};
TORCH_MODULE(ProbeNet);

constexpr int64_t kSceneLogits = 5 + 3 + 4 + 2;
// Splits scene logits into the four heads.
std::vector<torch::Tensor> split_scene_logits(const torch::Tensor& logits);

// Frechet distance between two sets of feature vectors [N, F] and [M, F] (Gaussians fitted to each):
// |mu1 - mu2|^2 + tr(S1 + S2 - 2 (S1 S2)^(1/2)), computed in float64 with a symmetric square root.
double frechet_distance(const torch::Tensor& a, const torch::Tensor& b);

}  // namespace gaia::probe
