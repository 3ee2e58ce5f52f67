#include "gaia/probe/probe.h"

#include "gaia/core/error.h"
#include "gaia/torch/conv_blocks.h"

namespace gaia::probe {

ProbeKind parse_kind(const std::string& s) {
  if (s == "dynamics") return ProbeKind::kDynamics;
  if (s == "scene") return ProbeKind::kScene;
  if (s == "realism") return ProbeKind::kRealism;
  fail("probe kind '{}' is not one of: dynamics, scene, realism", s);
}

std::string to_string(ProbeKind k) {
  return k == ProbeKind::kDynamics ? "dynamics" : k == ProbeKind::kScene ? "scene" : "realism";
}

const std::vector<std::string>& weather_classes() {
  static const std::vector<std::string> v{"clear", "overcast", "rain", "fog", "snow"};
  return v;
}
const std::vector<std::string>& time_classes() {
  static const std::vector<std::string> v{"day", "dusk", "night"};
  return v;
}
const std::vector<std::string>& light_classes() {
  static const std::vector<std::string> v{"none", "green", "amber", "red"};
  return v;
}
int class_index(const std::vector<std::string>& classes, const std::string& name) {
  for (size_t i = 0; i < classes.size(); ++i)
    if (classes[i] == name) return int(i);
  return -1;
}

ProbeNetImpl::ProbeNetImpl(ProbeKind k, int64_t n, int64_t width)
    : kind(k), frames(n > 0 ? n : (k == ProbeKind::kDynamics ? kDynamicsFrames : 1)) {
  if (kind != ProbeKind::kDynamics && frames != 1) fail("{} probe: reads one frame, not {}", to_string(kind), frames);
  if (kind == ProbeKind::kDynamics && frames < 2) fail("dynamics probe: needs at least 2 frames, got {}", frames);
  // Four stride-2 stages (72x128 -> 5x8), GroupNorm + SiLU, then the global average: small enough to train in
  // minutes on a CPU, deep enough to see lane markings move and the colour of a traffic light.
  const int64_t cin = 3 * in_frames();
  const int64_t w[5] = {cin, 32, 64, width, width};
  body = torch::nn::Sequential();
  for (int i = 0; i < 4; ++i) {
    body->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(w[i], w[i + 1], 3).stride(2).padding(1)));
    body->push_back(group_norm(w[i + 1]));
    body->push_back(torch::nn::SiLU());
    body->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(w[i + 1], w[i + 1], 3).padding(1)));
    body->push_back(group_norm(w[i + 1]));
    body->push_back(torch::nn::SiLU());
  }
  register_module("body", body);
  const int64_t outputs = kind == ProbeKind::kDynamics ? 2 : kind == ProbeKind::kScene ? kSceneLogits : 1;
  head = register_module("head", torch::nn::Linear(width, outputs));
}

torch::Tensor ProbeNetImpl::features(const torch::Tensor& x) {
  if (x.dim() != 4 || x.size(1) != 3 * in_frames())
    fail("{} probe: input must be [B, {}, H, W] ({} frames), got {}", to_string(kind), 3 * in_frames(), in_frames(),
         c10::str(x.sizes()));
  return body->forward(x).mean({2, 3});  // [B, width]
}

std::vector<torch::Tensor> split_scene_logits(const torch::Tensor& l) {
  return {l.slice(1, 0, 5), l.slice(1, 5, 8), l.slice(1, 8, 12), l.slice(1, 12, 14)};
}

double frechet_distance(const torch::Tensor& a, const torch::Tensor& b) {
  if (a.dim() != 2 || b.dim() != 2 || a.size(1) != b.size(1))
    fail("Frechet distance: feature sets must be [N, F] with the same F");
  if (a.size(0) < 2 || b.size(0) < 2) fail("Frechet distance: each set needs at least 2 samples");
  auto x = a.to(torch::kFloat64), y = b.to(torch::kFloat64);
  auto mu1 = x.mean(0), mu2 = y.mean(0);
  auto cov = [](const torch::Tensor& f, const torch::Tensor& mu) {
    auto c = f - mu;
    return c.t().matmul(c) / double(f.size(0) - 1);
  };
  auto s1 = cov(x, mu1), s2 = cov(y, mu2);
  // tr((S1 S2)^(1/2)) = tr((S1^(1/2) S2 S1^(1/2))^(1/2)): both factors symmetric PSD, so eigh suffices.
  auto sym_sqrt = [](const torch::Tensor& s) {
    auto [ev, V] = torch::linalg::eigh(s, "L");
    return V.matmul(torch::diag(ev.clamp_min(0).sqrt())).matmul(V.t());
  };
  auto r1 = sym_sqrt(s1);
  auto m = r1.matmul(s2).matmul(r1);
  auto ev = std::get<0>(torch::linalg::eigh((m + m.t()) / 2, "L")).clamp_min(0).sqrt();
  return ((mu1 - mu2).pow(2).sum() + s1.trace() + s2.trace() - 2 * ev.sum()).item<double>();
}

}  // namespace gaia::probe
