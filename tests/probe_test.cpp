// Evaluation probes: Frechet distance and Spearman against closed forms, shapes, learning on procedural data,
// exact resume through the CLI, and bad inputs.
#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include "gaia/core/safetensors.h"
#include "gaia/eval/metrics.h"
#include "gaia/probe/probe.h"
#include "gaia/probe/trainer.h"
#include "gaia/torch/tensor_io.h"
#include "test_util.h"

using namespace gaia;

namespace {
std::string q(const fs::path& p) { return "'" + p.string() + "'"; }
}  // namespace

TEST(Probe, FrechetDistanceClosedForms) {
  torch::manual_seed(0);
  auto a = torch::randn({400, 6}, torch::kFloat64) * torch::linspace(0.5, 2.0, 6, torch::kFloat64) + 1.0;
  EXPECT_NEAR(probe::frechet_distance(a, a), 0.0, 1e-8);
  // A shift d leaves the covariance alone: FD = |d|^2.
  auto d = torch::tensor({1.0, -2.0, 0.5, 0.0, 3.0, -1.0}, torch::kFloat64);
  EXPECT_NEAR(probe::frechet_distance(a, a + d), d.pow(2).sum().item<double>(), 1e-6);
  // b = 2a: mu2 = 2 mu1, S2 = 4 S1, so FD = |mu1|^2 + tr(S1 + 4 S1 - 2 (4 S1^2)^(1/2)) = |mu1|^2 + tr(S1).
  auto mu = a.mean(0), c = a - mu;
  const double want = mu.pow(2).sum().item<double>() + (c.t().matmul(c) / 399).trace().item<double>();
  EXPECT_NEAR(probe::frechet_distance(a, 2 * a), want, 1e-6 * want);
  EXPECT_NE(test::error_of([&] { probe::frechet_distance(a, a.slice(1, 0, 3)); }).find("same F"), std::string::npos);
}

TEST(Probe, SpearmanRanks) {
  EXPECT_DOUBLE_EQ(eval::spearman({1, 2, 3, 4}, {10, 20, 30, 400}), 1.0);
  EXPECT_DOUBLE_EQ(eval::spearman({1, 2, 3, 4}, {4, 3, 2, 1}), -1.0);
  EXPECT_DOUBLE_EQ(eval::spearman({1, 1, 1}, {1, 2, 3}), 0.0);
  // With ties: ranks (0.5, 0.5, 2) vs (0, 1, 2): Pearson of the ranks = 0.866...
  EXPECT_NEAR(eval::spearman({5, 5, 7}, {1, 2, 3}), std::sqrt(3.0) / 2, 1e-12);
}

TEST(Probe, ShapesAndBadInputs) {
  probe::ProbeNet dyn(probe::ProbeKind::kDynamics), scene(probe::ProbeKind::kScene);
  EXPECT_EQ(dyn->forward(torch::zeros({3, 6, 72, 128})).sizes(), (std::vector<int64_t>{3, 2}));
  EXPECT_EQ(scene->forward(torch::zeros({2, 3, 72, 128})).sizes(), (std::vector<int64_t>{2, probe::kSceneLogits}));
  EXPECT_EQ(scene->features(torch::zeros({2, 3, 32, 64})).sizes(), (std::vector<int64_t>{2, 128}));
  EXPECT_NE(test::error_of([&] { dyn->forward(torch::zeros({1, 3, 72, 128})); }).find("dynamics probe"), std::string::npos);
  EXPECT_NE(test::error_of([] { probe::parse_kind("speed"); }).find("'speed'"), std::string::npos);
  // Scores: a perfect scene prediction is 100% on every attribute.
  auto y = torch::tensor({{2, 1, 3, 1}, {0, 0, 0, 0}}, torch::kLong);
  auto logits = torch::zeros({2, probe::kSceneLogits});
  auto heads = probe::split_scene_logits(logits);
  for (int64_t i = 0; i < 2; ++i)
    for (size_t k = 0; k < 4; ++k) heads[k][i][y[i][int64_t(k)].item<int64_t>()] = 5.0;
  auto s = probe::score(probe::ProbeKind::kScene, logits, y);
  EXPECT_DOUBLE_EQ(s["weather_accuracy"].get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(s["lead_close_accuracy"].get<double>(), 1.0);
}

TEST(ProbeCli, LearnsAndResumesExactly) {
  test::TempDir d;
  auto r = test::run_gaia("synth --episodes 6 --seconds 3 --size 32x64 --seed 9 --out " + q(d / "ds"));
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 2";
  for (std::string kind : {"scene", "dynamics"}) {
    const std::string base = "probe train " + kind + " " + q(d / "ds") + tiny + " --steps 40 --batch 16 --val-every 20";
    r = test::run_gaia(base + " --out " + q(d / (kind + "-a")));
    ASSERT_EQ(r.status, 0) << r.output;
    r = test::run_gaia(base + " --stop-after 20 --out " + q(d / (kind + "-b")));
    ASSERT_EQ(r.status, 0) << r.output;
    r = test::run_gaia(base + " --out " + q(d / (kind + "-b")));
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_NE(r.output.find("resumed"), std::string::npos);
    const fs::path w = "probe-" + kind + ".safetensors";
    SafetensorsFile a(d / (kind + "-a") / w), b(d / (kind + "-b") / w);
    for (const auto& n : a.names()) ASSERT_TRUE(torch::equal(tensor_from_view(a.get(n)), tensor_from_view(b.get(n)))) << n;
    // The loss falls: mean of the last 10 steps well below the first 10.
    std::vector<double> loss;
    std::istringstream in(read_file(d / (kind + "-a") / "metrics.jsonl"));
    for (std::string line; std::getline(in, line);) loss.push_back(nlohmann::json::parse(line)["loss"].get<double>());
    ASSERT_EQ(loss.size(), 40u);
    double first = 0, last = 0;
    for (int i = 0; i < 10; ++i) first += loss[size_t(i)], last += loss[loss.size() - 1 - size_t(i)];
    EXPECT_LT(last, 0.8 * first) << kind;
    r = test::run_gaia("probe eval " + q(d / (kind + "-a") / w) + " " + q(d / "ds") + tiny + " --examples 32");
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_NE(r.output.find(kind == "scene" ? "weather_accuracy" : "steering_sign_accuracy"), std::string::npos) << r.output;
  }
  r = test::run_gaia("probe eval " + q(d / "ds" / "dataset.json") + " " + q(d / "ds") + tiny);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("dataset.json"), std::string::npos) << r.output;
}
