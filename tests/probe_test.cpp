// Evaluation probes: Frechet distance and Spearman against closed forms, shapes, learning on procedural data,
// exact resume through the CLI, the realism probe on real and procedural episodes, and bad inputs.
#include <algorithm>
#include <cmath>
#include <functional>
#include <random>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <torch/torch.h>

#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "gaia/data/frame_set.h"
#include "gaia/data/video_io.h"
#include "gaia/world/batch.h"
#include "gaia/eval/metrics.h"
#include "gaia/probe/probe.h"
#include "gaia/probe/trainer.h"
#include "gaia/tokenizer/io.h"
#include "gaia/torch/tensor_io.h"
#include "test_util.h"

using namespace gaia;
using test::q;

namespace {
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
  EXPECT_EQ(dyn->frames, probe::kDynamicsFrames);
  EXPECT_EQ(dyn->forward(torch::zeros({3, 3 * probe::kDynamicsFrames, 72, 128})).sizes(), (std::vector<int64_t>{3, 2}));
  EXPECT_EQ(scene->forward(torch::zeros({2, 3, 72, 128})).sizes(), (std::vector<int64_t>{2, probe::kSceneLogits}));
  EXPECT_EQ(scene->features(torch::zeros({2, 3, 32, 64})).sizes(), (std::vector<int64_t>{2, 128}));
  EXPECT_NE(test::error_of([&] { dyn->forward(torch::zeros({1, 6, 72, 128})); }).find("dynamics probe"), std::string::npos);
  EXPECT_NE(test::error_of([] { probe::parse_kind("speed"); }).find("'speed'"), std::string::npos);
  // A dynamics probe over K = 4 frames reads 12 channels; the scene probe reads one frame, dynamics at least two.
  probe::ProbeNet dyn4(probe::ProbeKind::kDynamics, 4);
  EXPECT_EQ(dyn4->forward(torch::zeros({2, 12, 32, 64})).sizes(), (std::vector<int64_t>{2, 2}));
  EXPECT_NE(test::error_of([&] { dyn4->forward(torch::zeros({2, 6, 32, 64})); }).find("(4 frames)"), std::string::npos);
  EXPECT_NE(test::error_of([] { probe::ProbeNet(probe::ProbeKind::kScene, 2); }).find("scene probe"), std::string::npos);
  EXPECT_NE(test::error_of([] { probe::ProbeNet(probe::ProbeKind::kDynamics, 1); }).find("at least 2"), std::string::npos);
  const auto span = probe::span_of(dyn4, Config{});  // one world-model step = 4 native frames at 25 / 6.25 Hz
  EXPECT_EQ(span.frames, 4);
  EXPECT_EQ(span.stride, 4);
  EXPECT_EQ(span.reach(), 12);
  EXPECT_EQ(probe::span_of(scene, Config{}).reach(), 0);
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

// Weights files say how many frames a dynamics probe reads; files from before that was recorded are pair probes,
// and a frame count that is not a number is one clear error naming the file.
TEST(Probe, FrameCountComesFromTheWeightsFile) {
  test::TempDir d;
  probe::ProbeNet pair(probe::ProbeKind::kDynamics, 2), six(probe::ProbeKind::kDynamics, 6);
  save_module(*pair, d / "legacy.safetensors", {{"gaia.component", "probe"}, {"gaia.probe.kind", "dynamics"}});
  save_module(*six, d / "six.safetensors",
              {{"gaia.component", "probe"}, {"gaia.probe.kind", "dynamics"}, {"gaia.probe.frames", "6"}});
  save_module(*six, d / "bad.safetensors",
              {{"gaia.component", "probe"}, {"gaia.probe.kind", "dynamics"}, {"gaia.probe.frames", "six"}});
  EXPECT_EQ(probe::load_probe(d / "legacy.safetensors", torch::kCPU)->frames, 2);
  auto loaded = probe::load_probe(d / "six.safetensors", torch::kCPU);
  EXPECT_EQ(loaded->frames, 6);
  EXPECT_TRUE(torch::equal(loaded->body->parameters()[0], six->body->parameters()[0]));  // [32, 18, 3, 3]
  auto err = test::error_of([&] { probe::load_probe(d / "bad.safetensors", torch::kCPU); });
  EXPECT_NE(err.find("bad.safetensors"), std::string::npos) << err;
  EXPECT_NE(err.find("gaia.probe.frames"), std::string::npos) << err;
}

TEST(ProbeCli, LearnsAndResumesExactly) {
  test::TempDir d;
  auto r = test::run_gaia("synth --episodes 6 --seconds 3 --size 32x64 --seed 9 --out " + q(d / "ds"));
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  for (std::string kind : {"scene", "dynamics"}) {
    const std::string base = "probe train " + kind + " " + q(d / "ds") + tiny + " --steps 40 --batch 16 --val-every 20";  // --batch: the old spelling of --batch-size
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
    r = test::run_gaia("probe eval " + q(d / "ds") + " --probe " + q(d / (kind + "-a") / w) + tiny + " --examples 32");
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_NE(r.output.find(kind == "scene" ? "weather_accuracy" : "steering_sign_accuracy"), std::string::npos) << r.output;
  }
  // A dynamics probe over 3 frames: its inputs are the frames i, i + s, i + 2 s and its targets the mean speed and
  // curvature over the native frames i .. i + 2 s; the file says how many frames it reads, and eval reads them.
  {
    data::Dataset ds(d / "ds");
    auto set = data::frame_set(ds, ds.ids(), 8, 6);
    const probe::Span span{3, 4};
    auto x = probe::inputs(set.episodes, set.frames, span);
    auto y = probe::targets(probe::ProbeKind::kDynamics, set.episodes, set.frames, span);
    ASSERT_EQ(x.sizes(), (std::vector<int64_t>{6, 9, 32, 64}));
    for (size_t i = 0; i < set.frames.size(); ++i) {
      const auto& e = set.frames[i];
      const auto& ep = *set.episodes[e.episode];
      EXPECT_TRUE(torch::equal(x[int64_t(i)].slice(0, 6, 9), probe::probe_input({ep.frame_bgr(e.frame + 8)})));
      double sp = 0, cu = 0;
      for (int64_t k = e.frame; k <= e.frame + 8; ++k) sp += ep.speed(k) / 9, cu += ep.curvature(k) / 9;
      EXPECT_NEAR(y[int64_t(i)][0].item<double>(), sp / world::kSpeedScale, 1e-5);
      EXPECT_NEAR(y[int64_t(i)][1].item<double>(), cu / world::kCurvatureScale, 1e-4);
    }
  }
  r = test::run_gaia("probe train dynamics " + q(d / "ds") + tiny + " --frames 3 --steps 4 --batch-size 4 --out " + q(d / "dyn3"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(SafetensorsFile(d / "dyn3" / "probe-dynamics.safetensors").metadata().at("gaia.probe.frames"), "3");
  EXPECT_EQ(probe::load_probe(d / "dyn3" / "probe-dynamics.safetensors", torch::kCPU)->frames, 3);
  // The old spelling (weights first, positional) still works for a release, and says what to write instead.
  r = test::run_gaia("probe eval " + q(d / "dyn3" / "probe-dynamics.safetensors") + " " + q(d / "ds") + tiny + " --examples 8");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("\"frames\": 3"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("use DATASET --probe WEIGHTS"), std::string::npos) << r.output;
  r = test::run_gaia("probe eval " + q(d / "ds") + tiny);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--probe WEIGHTS is required"), std::string::npos) << r.output;
  r = test::run_gaia("probe train scene " + q(d / "ds") + tiny + " --frames 2 --steps 4 --out " + q(d / "scene2"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("scene probe: reads one frame"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "scene2" / "probe-scene.safetensors"));

  r = test::run_gaia("probe eval " + q(d / "ds") + " --probe " + q(d / "ds" / "dataset.json") + tiny);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("dataset.json"), std::string::npos) << r.output;
}

// Frames read through the tokenizer (--tokenizer): the flagged examples are the tokenizer's reconstruction of the
// frame, the others the raw frame; training with a decoded share resumes exactly and validates on decoded frames
// too; bad shares and a tokenizer of another frame size fail with one line naming them.
TEST(ProbeCli, ReadsFramesThroughTheTokenizer) {
  test::TempDir d;
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  auto r = test::run_gaia("synth --episodes 6 --seconds 2 --size 32x64 --seed 5 --out " + q(d / "ds"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("tokenizer train " + q(d / "ds") + tiny + " --steps 6 --out " + q(d / "tok"));
  ASSERT_EQ(r.status, 0) << r.output;
  const fs::path tok_file = d / "tok" / "tokenizer.safetensors";

  data::Dataset ds(d / "ds");
  auto set = data::frame_set(ds, ds.ids(), 0, 4);
  ASSERT_EQ(set.frames.size(), 4u);
  auto tok = probe::load_through(tok_file, set.episodes[0]->frame_bgr(0), d / "ds", torch::kCPU);
  const probe::Span one;
  auto x = probe::inputs(set.episodes, set.frames, one, {&tok, torch::kCPU}, {true, false, true, false});
  // The same frame through the tokenizer in batches of other sizes: the convolutions may take other kernels by batch
  // size and CPU, so a decoded frame agrees to far below what the tokenizer itself changes (a tenth of it), not bit
  // for bit. Raw frames are copied, so those are equal.
  std::vector<double> changed(4);
  auto near = [&](const torch::Tensor& a, const torch::Tensor& b, size_t i) {
    return (a - b).abs().mean().item<double>() < changed[i] / 10;
  };
  for (size_t i = 0; i < 4; ++i) {
    const auto& e = set.frames[i];
    const cv::Mat raw = set.episodes[e.episode]->frame_bgr(e.frame);
    const cv::Mat back = tokenizer::decode_tokens(tok, tokenizer::encode_frames(tok, {raw}, torch::kCPU), torch::kCPU)[0];
    // The tokenizer changes the frame: the flag is what decides, not a no-op.
    changed[i] = (probe::probe_input({back}) - probe::probe_input({raw})).abs().mean().item<double>();
    EXPECT_GT(changed[i], 1e-3) << i;
    if (i % 2 == 0) EXPECT_TRUE(near(x[int64_t(i)], probe::probe_input({back}), i)) << i;
    else EXPECT_TRUE(torch::equal(x[int64_t(i)], probe::probe_input({raw}))) << i;
  }
  // Every example through it when no flags are given (validation and `probe eval`).
  auto all = probe::inputs(set.episodes, set.frames, one, {&tok, torch::kCPU});
  EXPECT_TRUE(near(all[0], x[0], 0));
  EXPECT_TRUE(near(all[2], x[2], 2));
  EXPECT_FALSE(near(all[1], x[1], 1));

  const std::string base = "probe train scene " + q(d / "ds") + tiny + " --tokenizer " + q(tok_file) +
                           " --decoded-share 0.5 --steps 8 --batch-size 8 --val-every 4";
  r = test::run_gaia(base + " --out " + q(d / "a"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(base + " --stop-after 4 --out " + q(d / "b"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(base + " --out " + q(d / "b"));
  ASSERT_EQ(r.status, 0) << r.output;
  const fs::path w = "probe-scene.safetensors";
  SafetensorsFile a(d / "a" / w), b(d / "b" / w);
  for (const auto& n : a.names()) ASSERT_TRUE(torch::equal(tensor_from_view(a.get(n)), tensor_from_view(b.get(n)))) << n;
  EXPECT_EQ(a.metadata().at("gaia.probe.decoded_share"), "0.5");
  std::istringstream in(read_file(d / "a" / "metrics.jsonl"));
  int validated = 0;
  for (std::string line; std::getline(in, line);) {
    auto j = nlohmann::json::parse(line);
    if (j["val"].is_null() || j["val"].empty()) continue;
    ++validated;
    const double acc = j["val"]["decoded"]["weather_accuracy"].get<double>();
    EXPECT_GE(acc, 0.0);
    EXPECT_LE(acc, 1.0);
  }
  EXPECT_EQ(validated, 2);
  // Without --tokenizer the file says no frame was decoded.
  r = test::run_gaia("probe train scene " + q(d / "ds") + tiny + " --steps 2 --batch-size 4 --out " + q(d / "raw"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(SafetensorsFile(d / "raw" / w).metadata().at("gaia.probe.decoded_share"), "0");

  r = test::run_gaia("probe eval " + q(d / "ds") + " --probe " + q(d / "a" / w) + tiny + " --examples 16 --tokenizer " + q(tok_file));
  ASSERT_EQ(r.status, 0) << r.output;
  auto j = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  EXPECT_EQ(j["decoded"]["examples"].get<int>(), j["examples"].get<int>());
  EXPECT_TRUE(j["decoded"].contains("weather_accuracy")) << r.output;

  r = test::run_gaia(base + " --decoded-share 1.5 --out " + q(d / "c"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--decoded-share"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "c" / w));
  r = test::run_gaia("probe train scene " + q(d / "ds") + tiny + " --steps 2 --decoded-share 0.5 --out " + q(d / "f"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--tokenizer"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "f"));
  r = test::run_gaia("synth --episodes 2 --seconds 1 --size 24x48 --seed 5 --out " + q(d / "small"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("probe train scene " + q(d / "small") + tiny + " --steps 2 --tokenizer " + q(tok_file) + " --out " +
                     q(d / "e"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("tokenizer.safetensors"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("32x64"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "e" / w));
}

// Held-out drives too short for what a probe reads (0.2 s, while the dynamics probe spans 4 world-model steps)
// are one error line naming the dataset, not LibTorch's complaint about an empty list.
TEST(ProbeCli, EvalOnDrivesTooShortForTheProbeIsOneLine) {
  test::TempDir d;
  test::synth_dataset(d / "ds", 3, 0.2);
  auto r = test::run_gaia("probe eval " + q(d / "ds") + " --probe " +
                          q(test::source_dir() / "models" / "probe-dynamics.safetensors") + " --threads 1");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_EQ(r.output.rfind("gaia: error: ", 0), 0u) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_NE(r.output.find("no held-out episode is long enough for this probe"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find((d / "ds").string()), std::string::npos) << r.output;
}

namespace {

// A "camera" clip: a sensor-noise texture with a bright band that moves, nothing like the procedural world's flat
// shading. Written as MJPEG (FFmpeg always has it) at 25 fps.
fs::path camera_clip(const fs::path& p, int frames, int seed) {
  cv::VideoWriter vw(p.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25.0, cv::Size(128, 64));
  if (!vw.isOpened()) return {};
  cv::RNG rng(static_cast<uint64_t>(seed) + 1);
  for (int i = 0; i < frames; ++i) {
    cv::Mat f(64, 128, CV_8UC3);
    rng.fill(f, cv::RNG::NORMAL, cv::Scalar(110, 120, 130), cv::Scalar(45, 45, 45));
    cv::rectangle(f, cv::Rect((i * 5 + seed * 17) % 128, 0, 12, 64), cv::Scalar(230, 230, 230), cv::FILLED);
    vw.write(f);
  }
  return p;
}

}  // namespace

// The realism probe: trained on one dataset of real (ingested) and procedural (gaia synth) episodes, half of each
// batch from each, it tells the held-out clip from held-out procedural drives; `gaia probe read` reads a video and a
// rollout; a dataset whose training episodes are all of one kind is one error line.
TEST(ProbeCli, RealismTellsRealFootageFromProcedural) {
  test::TempDir d;
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  auto r = test::run_gaia("synth --episodes 4 --seconds 2 --size 32x64 --seed 9 --out " + q(d / "ds"));
  ASSERT_EQ(r.status, 0) << r.output;
  for (int i = 0; i < 3; ++i) {
    const fs::path clip = camera_clip(d / fmt::format("cam{}.avi", i), 30, i);
    ASSERT_FALSE(clip.empty());
    r = test::run_gaia("ingest " + q(clip) + tiny + " --id cam" + std::to_string(i) + " --out " + q(d / "ds"));
    ASSERT_EQ(r.status, 0) << r.output;
  }
  // Leave one clip out (and one procedural drive, so both kinds are scored).
  r = test::run_gaia("data split " + q(d / "ds") + " --hold-out cam2 --hold-out synth-s9-e00003" + tiny);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("2 named"), std::string::npos) << r.output;
  r = test::run_gaia("probe train realism " + q(d / "ds") + tiny + " --steps 150 --batch-size 16 --val-every 150 --out " +
                     q(d / "real"));
  ASSERT_EQ(r.status, 0) << r.output;
  const fs::path w = d / "real" / "probe-realism.safetensors";
  ASSERT_TRUE(fs::exists(w));
  r = test::run_gaia("probe eval " + q(d / "ds") + " --probe " + q(w) + tiny + " --examples 40");
  ASSERT_EQ(r.status, 0) << r.output;
  auto j = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  EXPECT_EQ(j.at("real_examples").get<int>(), 20);  // half of the 40 from the held-out clip
  EXPECT_EQ(j.at("procedural_examples").get<int>(), 20);
  EXPECT_GE(j.at("real_read_as_real").get<double>(), 0.9) << j;
  EXPECT_LE(j.at("procedural_read_as_real").get<double>(), 0.1) << j;

  // probe read: the held-out clip reads as real; a procedural drive's frames (as a video) do not.
  r = test::run_gaia("probe read " + q(d / "cam2.avi") + " --probe " + q(w) + tiny + " --out " + q(d / "read"));
  ASSERT_EQ(r.status, 0) << r.output;
  j = nlohmann::json::parse(read_file(d / "read" / "probe_read.json"));
  EXPECT_EQ(j.at("frames").get<int>(), 30);
  EXPECT_GE(j.at("read_as_real").get<double>(), 0.9) << j;
  std::vector<cv::Mat> synth_frames;
  {
    data::Dataset ds(d / "ds");
    auto set = data::frame_set(ds, {"synth-s9-e00003"}, 0, 20);
    for (auto& f : set.frames) synth_frames.push_back(set.episodes[f.episode]->frame_bgr(f.frame));
  }
  data::write_video(d / "synth.mp4", synth_frames, 25);
  r = test::run_gaia("probe read " + q(d / "synth.mp4") + " --probe " + q(w) + tiny);
  ASSERT_EQ(r.status, 0) << r.output;
  j = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  EXPECT_LE(j.at("read_as_real").get<double>(), 0.2) << j;

  // A rollout's tokens need a tokenizer to be read; a dynamics probe reads no single frames.
  r = test::run_gaia("probe read " + q(w) + " --probe " + q(w) + tiny);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("give --tokenizer"), std::string::npos) << r.output;
  r = test::run_gaia("probe read " + q(d / "cam2.avi") + " --probe " +
                     q(test::source_dir() / "models" / "probe-dynamics.safetensors") + tiny);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("is a dynamics probe"), std::string::npos) << r.output;

  // Every real clip held out: nothing real to learn from.
  r = test::run_gaia("data split " + q(d / "ds") + " --hold-out cam0 --hold-out cam1 --hold-out cam2" + tiny);
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("probe train realism " + q(d / "ds") + tiny + " --steps 2 --out " + q(d / "none"));
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_NE(r.output.find("needs real and procedural episodes"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "none" / "probe-realism.safetensors"));
}

// The scene probe on recorded footage: an episode without per-frame labels is labelled by its metadata (weather and
// time of day, a manifest's columns), its light state and lead vehicle left out of the loss and the accuracies; one
// whose metadata gives neither is one error line naming it.
TEST(ProbeCli, SceneProbeLearnsRecordedFootageFromItsMetadata) {
  test::TempDir d;
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  auto r = test::run_gaia("synth --episodes 4 --seconds 2 --size 32x64 --seed 9 --out " + q(d / "ds"));
  ASSERT_EQ(r.status, 0) << r.output;
  // Two drives become recorded footage: no per-frame labels, a camera's source; their metadata keeps the scene's
  // weather and time of day, as a manifest's columns give them.
  auto recorded = [&](const std::string& id, const std::function<void(nlohmann::json&)>& edit = {}) {
    const fs::path e = d / "ds" / "episodes" / id;
    fs::remove(e / "labels.jsonl");
    auto j = nlohmann::json::parse(read_file(e / "episode.json"));
    j["source"] = "dashcam.mp4";
    if (edit) edit(j);
    write_file_atomic(e / "episode.json", j.dump(2));
  };
  recorded("synth-s9-e00000");
  recorded("synth-s9-e00001");
  r = test::run_gaia("data split " + q(d / "ds") + " --hold-out synth-s9-e00000" + tiny);
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("probe train scene " + q(d / "ds") + tiny + " --steps 60 --batch-size 16 --val-every 60 --out " +
                     q(d / "scene"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("probe eval " + q(d / "ds") + " --probe " + q(d / "scene" / "probe-scene.safetensors") + tiny +
                     " --examples 16");
  ASSERT_EQ(r.status, 0) << r.output;
  auto j = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  // Only the recorded drive is held out: weather and time of day are scored, light and lead have no label to score.
  EXPECT_TRUE(j["light_state_accuracy"].is_null()) << j;
  EXPECT_TRUE(j["lead_close_accuracy"].is_null()) << j;
  EXPECT_EQ(j["examples"].get<int>(), 16);
  for (const char* k : {"weather_accuracy", "time_of_day_accuracy"}) {  // a share of the 16 labelled frames
    const double a = j[k].get<double>();
    EXPECT_GE(a, 0.0) << k;
    EXPECT_LE(a, 1.0) << k;
    EXPECT_NEAR(a * 16, std::round(a * 16), 1e-9) << k;
  }

  recorded("synth-s9-e00002", [](nlohmann::json& j) {
    j["weather"] = "";
    j["time_of_day"] = "twilight";
  });
  r = test::run_gaia("probe train scene " + q(d / "ds") + tiny + " --steps 2 --out " + q(d / "bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_NE(r.output.find("synth-s9-e00002: no labels.jsonl, and its metadata gives no weather or time_of_day"),
            std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "bad" / "probe-scene.safetensors"));
}

// The dynamics probe on recorded footage whose estimated signals have gaps: windows reaching a frame without a speed
// or curvature are left out of training and scoring (exactly those), the held-out recorded frames are scored on
// their own ("real"), --mirror flips half of each batch with its curvature negated, and only for dynamics.
TEST(ProbeCli, DynamicsProbeLearnsRecordedFootageWithGaps) {
  test::TempDir d;
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  auto r = test::run_gaia("synth --episodes 4 --seconds 3 --size 32x64 --seed 9 --out " + q(d / "ds"));
  ASSERT_EQ(r.status, 0) << r.output;
  // Two drives become recorded footage whose estimate could not read frames 20-29 and 40-44.
  for (const std::string id : {"synth-s9-e00000", "synth-s9-e00001"}) {
    const fs::path e = d / "ds" / "episodes" / id;
    fs::remove(e / "labels.jsonl");
    auto j = nlohmann::json::parse(read_file(e / "episode.json"));
    j["source"] = "dashcam.mp4";
    j["signals_source"] = "estimated";
    write_file_atomic(e / "episode.json", j.dump(2));
    auto speed = npy_read(e / "speed.npy").to_double();
    std::vector<float> v(speed.begin(), speed.end());
    for (int i = 20; i < 30; ++i) v[size_t(i)] = std::nanf("");
    for (int i = 40; i < 45; ++i) v[size_t(i)] = std::nanf("");
    npy_write(e / "speed.npy", npy_make(DType::F32, {int64_t(v.size())}, v));
  }
  {
    data::Dataset ds(d / "ds");
    auto set = data::frame_set(ds, {"synth-s9-e00000"}, 12, 0);
    const size_t all = set.frames.size();
    const probe::Span span{4, 4};
    // Starts f whose frames f .. f + 12 reach 20-29 or 40-44: f in 8..29 and 28..44, i.e. 8..44 (37 starts).
    EXPECT_EQ(probe::keep_with_signals(set, span), 37u);
    EXPECT_EQ(set.frames.size(), all - 37);
    for (const auto& e : set.frames) EXPECT_TRUE(e.frame < 8 || e.frame > 44) << e.frame;
  }
  r = test::run_gaia("data split " + q(d / "ds") + " --hold-out synth-s9-e00000 --hold-out synth-s9-e00003" + tiny);
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("probe train dynamics " + q(d / "ds") + tiny + " --mirror --steps 30 --batch-size 8 --out " +
                     q(d / "dyn"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("examples left out: a frame of theirs has no speed or curvature"), std::string::npos)
      << r.output;
  r = test::run_gaia("probe eval " + q(d / "ds") + " --probe " + q(d / "dyn" / "probe-dynamics.safetensors") + tiny +
                     " --examples 40");
  ASSERT_EQ(r.status, 0) << r.output;
  auto j = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  // The held-out recorded drive and the procedural one: the recorded frames apart, fewer (its gaps are left out).
  ASSERT_TRUE(j.contains("real")) << j;
  const int all = j["examples"].get<int>(), real = j["real"]["examples"].get<int>();
  EXPECT_GT(real, 0);
  EXPECT_LT(real, all - real) << j;
  EXPECT_TRUE(std::isfinite(j["real"]["curvature_bias_per_m"].get<double>())) << j;

  r = test::run_gaia("probe train scene " + q(d / "ds") + tiny + " --mirror --steps 2 --out " + q(d / "bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--mirror is for the dynamics probe"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "bad"));
}

// Mirror image of dynamics examples: the flagged rows' frames flipped left to right and their curvature negated, the
// others and every speed untouched.
TEST(Probe, MirroredDynamicsExamplesTurnTheOtherWay) {
  torch::manual_seed(5);
  auto x = torch::rand({3, 12, 8, 10}), y = torch::tensor({{0.5f, 0.2f}, {0.7f, -0.3f}, {0.1f, 0.4f}});
  auto mx = x.clone(), my = y.clone();
  probe::mirror_dynamics(mx, my, {false, true, true});
  EXPECT_TRUE(torch::equal(mx[0], x[0]));
  EXPECT_TRUE(torch::equal(mx[1], x[1].flip({2})));
  EXPECT_TRUE(torch::equal(mx[2].select(2, 0), x[2].select(2, 9)));
  EXPECT_TRUE(torch::equal(my.select(1, 0), y.select(1, 0)));
  EXPECT_FLOAT_EQ(my[0][1].item<float>(), 0.2f);
  EXPECT_FLOAT_EQ(my[1][1].item<float>(), 0.3f);
  EXPECT_FLOAT_EQ(my[2][1].item<float>(), -0.4f);
}

// The realism probe's augmentation: shape and range kept, the same draws for the same seed, and each example changed
// on its own (a grey example beside a coloured one).
TEST(Probe, RealismAugmentationIsSeededAndStaysInRange) {
  torch::manual_seed(3);
  auto x = torch::rand({16, 3, 24, 32}) * 2 - 1;
  std::mt19937_64 a(7), b(7), c(8);
  auto ya = probe::realism_augment(x, a), yb = probe::realism_augment(x, b), yc = probe::realism_augment(x, c);
  ASSERT_EQ(ya.sizes(), x.sizes());
  EXPECT_TRUE(torch::equal(ya, yb));
  EXPECT_FALSE(torch::equal(ya, yc));
  EXPECT_LE(ya.abs().max().item<float>(), 1.0f);
  int grey = 0;
  for (int64_t i = 0; i < 16; ++i) {
    EXPECT_FALSE(torch::allclose(ya[i], x[i]));
    grey += (ya[i][0] - ya[i][1]).abs().max().item<float>() < 1e-6 && (ya[i][1] - ya[i][2]).abs().max().item<float>() < 1e-6;
  }
  EXPECT_GE(grey, 1);   // a quarter are grey on average: at least one of 16 ...
  EXPECT_LE(grey, 12);  // ... and not all
}
