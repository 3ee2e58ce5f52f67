// The video decoder end to end through the CLI on tiny data: synth -> tokenizer -> decoder train (interrupted and
// resumed: identical weights to an uninterrupted run) -> decode (MP4, GIF, PNG; --fast) -> eval, and bad inputs.
#include <algorithm>
#include <sstream>

#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "gaia/decoder/evaluate.h"
#include "gaia/decoder/io.h"
#include "gaia/tokenizer/io.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "test_util.h"

using namespace gaia;
using test::q;

namespace {

// A tiny procedural dataset and a tokenizer trained on it, built once for the whole suite (test::shared_fixture);
// each test writes its own outputs under `dir`.
struct DecoderPipeline {
  test::TempDir dir;
  fs::path ds, tok;
  DecoderPipeline() {
    const fs::path shared = test::shared_fixture("decoder-cli", [&](const fs::path& d) {
      auto r = test::run_gaia("synth --episodes 4 --seconds 3 --size 32x64 --seed 4 --out " + q(d / "ds"));
      if (r.status != 0) throw std::runtime_error(r.output);
      r = test::run_gaia("tokenizer train " + q(d / "ds") + tiny() + " --steps 10 --out " + q(d / "tok"));
      if (r.status != 0) throw std::runtime_error(r.output);
    });
    ds = shared / "ds";
    tok = shared / "tok";
  }
  static DecoderPipeline& get() {
    static DecoderPipeline p;
    return p;
  }
  static std::string tiny() { return " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1"; }
  std::string tokenizer() const { return " --tokenizer " + q(tok / "tokenizer.safetensors"); }
};

}  // namespace

TEST(DecoderCli, TrainResumesExactlyThenDecodes) {
  auto& p = DecoderPipeline::get();
  const std::string base = "decoder train " + q(p.ds) + p.tokenizer() + p.tiny() + " --steps 6 --val-every 3";
  auto r = test::run_gaia(base + " --out " + q(p.dir / "straight"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(base + " --stop-after 3 --out " + q(p.dir / "resumed"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "resumed" / "decoder.safetensors"));
  EXPECT_TRUE(fs::exists(p.dir / "resumed" / "latest.safetensors"));  // EMA weights so far
  r = test::run_gaia(base + " --out " + q(p.dir / "resumed"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("resumed"), std::string::npos) << r.output;
  SafetensorsFile a(p.dir / "straight" / "decoder.safetensors"), b(p.dir / "resumed" / "decoder.safetensors");
  ASSERT_EQ(a.names(), b.names());
  for (const auto& n : a.names())
    ASSERT_TRUE(torch::equal(tensor_from_view(a.get(n)), tensor_from_view(b.get(n)))) << n;
  // metrics.jsonl has a validation entry with a loss.
  auto lines = read_file(p.dir / "straight" / "metrics.jsonl");
  EXPECT_NE(lines.find("\"x0_psnr\""), std::string::npos);

  // Decode 5 token frames of a rollout-shaped file with 2 futures to 25 Hz: 4 * 5 - 3 = 17 frames.
  auto tokens = torch::randint(0, 256, {2, 5, 4, 8}, torch::kInt);
  save_tensors({{"tokens", tokens}}, p.dir / "rollout.safetensors");
  r = test::run_gaia("decode " + q(p.dir / "rollout.safetensors") + p.tokenizer() + " --decoder " +
                     q(p.dir / "straight" / "decoder.safetensors") + " --ddim-steps 2" + p.tiny() + " --out " +
                     q(p.dir / "out" / "video.mp4"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("17 frames at 25 Hz"), std::string::npos) << r.output;
  for (auto f : {"video.mp4", "video.gif", "video.png"}) EXPECT_GT(fs::file_size(p.dir / "out" / f), 100u) << f;
  // --precision bf16: the U-Net under autocast (DecoderVideo.Bf16DecodingStaysNearFloat32); fp32 where the CPU lacks it.
  r = test::run_shell(test::gaia_command("decode " + q(p.dir / "rollout.safetensors") + p.tokenizer() +
                                         " --decoder " + q(p.dir / "straight" / "decoder.safetensors") +
                                         " --ddim-steps 2 --precision bf16" + p.tiny() + " --out " +
                                         q(p.dir / "bf16" / "video.mp4")) + " 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("17 frames at 25 Hz"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("running in fp32 instead") != std::string::npos, !cpu_has_bf16()) << r.output;
  // --fast: the tokenizer's decoder, at the token rate.
  r = test::run_gaia("decode " + q(p.dir / "rollout.safetensors") + p.tokenizer() + " --fast" + p.tiny() + " --out " +
                     q(p.dir / "fast.mp4"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("5 frames at 6.25 Hz"), std::string::npos) << r.output;

  r = test::run_gaia("decoder eval " + q(p.ds) + p.tokenizer() + " --decoder " + q(p.dir / "straight" / "decoder.safetensors") +
                     " --clips 1 --token-frames 3 --steps 2,1" + p.tiny() + " --out " + q(p.dir / "eval"));
  ASSERT_EQ(r.status, 0) << r.output;
  // The progress bar is made at the first report, after a window's work: its rate counts from there, not the
  // whole first window over the microseconds since the bar was made.
  ASSERT_NE(r.output.find("/s elapsed"), std::string::npos) << r.output;
  for (size_t at = r.output.find("/s elapsed"); at != std::string::npos; at = r.output.find("/s elapsed", at + 1)) {
    const size_t from = r.output.rfind(' ', at) + 1;
    EXPECT_LT(std::stod(r.output.substr(from, at - from)), 1e4) << r.output;
  }
  auto j = nlohmann::json::parse(read_file(p.dir / "eval" / "eval.json"));
  EXPECT_EQ(j["frames_25hz"].get<int>(), 9);
  ASSERT_EQ(j["clip_starts"].size(), 1u);  // where the scored clip lies: a held-out episode, past its start
  EXPECT_GT(j["clip_starts"][0]["start_s"].get<double>(), 0.0);
  EXPECT_GT(j["video_decoder"]["2"]["psnr_25hz"].get<double>(), 0);
  EXPECT_GT(j["tokenizer_decoder"]["psnr_6.25hz"].get<double>(), 0);
  // The blended baseline has the tokenizer decoder's key frames and only blends between them.
  const auto& blended = j["tokenizer_decoder_blended"];
  EXPECT_EQ(blended["psnr_6.25hz"].get<double>(), j["tokenizer_decoder"]["psnr_6.25hz"].get<double>());
  EXPECT_NE(blended["psnr_25hz"].get<double>(), j["tokenizer_decoder"]["psnr_25hz"].get<double>());
  EXPECT_GT(j["video_decoder"]["1"]["seconds_per_ddim_step"].get<double>(), 0);
  EXPECT_GT(j["ground_truth"]["edge_energy"].get<double>(), 0);
  EXPECT_GT(j["video_decoder"]["1"]["sharpness"].get<double>(), 0);
  EXPECT_GT(j["tokenizer_decoder_blended"]["sharpness"].get<double>(), 0);
  EXPECT_EQ(j["noise_correlation"].get<double>(), 0.0);
  EXPECT_EQ(j["noise_scale"].get<double>(), gaia::Config().decoder.noise_scale);  // the built-in default

  // --set reaches the sampling options of the decoder read from its file; its architecture is the file's.
  r = test::run_gaia("decoder eval " + q(p.ds) + p.tokenizer() + " --decoder " + q(p.dir / "straight" / "decoder.safetensors") +
                     " --clips 1 --token-frames 3 --steps 2 --set decoder.noise_correlation=1 --set decoder.noise_scale=0.5" +
                     " --set decoder.start_time=0.6" + p.tiny() + " --out " +
                     q(p.dir / "eval-r1"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto j1 = nlohmann::json::parse(read_file(p.dir / "eval-r1" / "eval.json"));
  EXPECT_EQ(j1["noise_correlation"].get<double>(), 1.0);
  EXPECT_EQ(j1["noise_scale"].get<double>(), 0.5);
  EXPECT_EQ(j1["start_time"].get<double>(), 0.6);
  EXPECT_EQ(j["start_time"].get<double>(), gaia::Config().decoder.start_time);  // the built-in default
  EXPECT_NE(j1["video_decoder"]["2"]["psnr_25hz"].get<double>(), j["video_decoder"]["2"]["psnr_25hz"].get<double>());
  // --token-fps 25: the video decoder gets every frame's tokens (no upsampling windows), as the tokenizer decoder
  // does; the baselines do not change, the video decoder's frames do. Another rate is one clear error.
  r = test::run_gaia("decoder eval " + q(p.ds) + p.tokenizer() + " --decoder " + q(p.dir / "straight" / "decoder.safetensors") +
                     " --clips 1 --token-frames 3 --steps 2 --token-fps 25" + p.tiny() + " --out " + q(p.dir / "eval-25"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto j25 = nlohmann::json::parse(read_file(p.dir / "eval-25" / "eval.json"));
  EXPECT_EQ(j25["token_fps"].get<double>(), 25.0);
  EXPECT_EQ(j["token_fps"].get<double>(), 6.25);
  EXPECT_EQ(j25["frames_25hz"].get<int>(), 9);
  EXPECT_EQ(j25["tokenizer_decoder"]["psnr_25hz"].get<double>(), j["tokenizer_decoder"]["psnr_25hz"].get<double>());
  EXPECT_NE(j25["video_decoder"]["2"]["psnr_25hz"].get<double>(), j["video_decoder"]["2"]["psnr_25hz"].get<double>());
  r = test::run_gaia("decoder eval " + q(p.ds) + p.tokenizer() + " --decoder " + q(p.dir / "straight" / "decoder.safetensors") +
                     " --clips 1 --token-frames 3 --steps 2 --token-fps 10" + p.tiny() + " --out " + q(p.dir / "eval-10"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--token-fps must be 6.25, 12.5 or 25, got 10"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "eval-10" / "eval.json"));
  // --footage: held-out drives of that footage only; this dataset is procedural, so real footage has none to score.
  EXPECT_EQ(j["footage"].get<std::string>(), "any");
  r = test::run_gaia("decoder eval " + q(p.ds) + p.tokenizer() + " --decoder " + q(p.dir / "straight" / "decoder.safetensors") +
                     " --clips 1 --token-frames 3 --steps 1 --footage real" + p.tiny() + " --out " + q(p.dir / "eval-real"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("no held-out episode of real footage has 9 frames"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "eval-real" / "eval.json"));
  r = test::run_gaia("decode " + q(p.dir / "rollout.safetensors") + p.tokenizer() + " --decoder " +
                     q(p.dir / "straight" / "decoder.safetensors") + " --ddim-steps 1 --set decoder.channels=64" + p.tiny() +
                     " --out " + q(p.dir / "out2" / "video.mp4"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("decoder.channels comes from the weights file"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "out2" / "video.mp4"));
  r = test::run_gaia("decode " + q(p.dir / "rollout.safetensors") + p.tokenizer() + " --decoder " +
                     q(p.dir / "straight" / "decoder.safetensors") + " --ddim-steps 1 --set decoder.noise_correlation=2" +
                     p.tiny() + " --out " + q(p.dir / "out2" / "video.mp4"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("decoder.noise_correlation"), std::string::npos) << r.output;
}

TEST(DecoderCli, BadInputsAreClearErrors) {
  auto& p = DecoderPipeline::get();
  // A token grid that does not match the tokenizer (tiny: 4x8).
  npy_write(p.dir / "grid.npy", npy_make<int16_t>(DType::I16, {3, 5, 8}, std::vector<int16_t>(3 * 5 * 8, 1)));
  auto r = test::run_gaia("decode " + q(p.dir / "grid.npy") + p.tokenizer() + " --fast" + p.tiny() + " --out " + q(p.dir / "x.mp4"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("does not match the tokenizer"), std::string::npos) << r.output;
  // An empty token file.
  npy_write(p.dir / "empty.npy", npy_make<int16_t>(DType::I16, {0, 4, 8}, std::vector<int16_t>{}));
  r = test::run_gaia("decode " + q(p.dir / "empty.npy") + p.tokenizer() + " --fast" + p.tiny() + " --out " + q(p.dir / "x.mp4"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("empty"), std::string::npos) << r.output;
  // Token ids outside the codebook.
  npy_write(p.dir / "big.npy", npy_make<int16_t>(DType::I16, {2, 4, 8}, std::vector<int16_t>(64, 300)));
  r = test::run_gaia("decode " + q(p.dir / "big.npy") + p.tokenizer() + " --fast" + p.tiny() + " --out " + q(p.dir / "x.mp4"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("[0, 256)"), std::string::npos) << r.output;
  // No decoder and no --fast; a missing tokens file; a decoder file that is not one.
  r = test::run_gaia("decode " + q(p.dir / "big.npy") + p.tokenizer() + p.tiny() + " --out " + q(p.dir / "x.mp4"));
  EXPECT_NE(r.output.find("--decoder"), std::string::npos) << r.output;
  r = test::run_gaia("decode " + q(p.dir / "nope.npy") + p.tokenizer() + " --fast" + p.tiny() + " --out " + q(p.dir / "x.mp4"));
  EXPECT_NE(r.output.find("nope.npy"), std::string::npos) << r.output;
  npy_write(p.dir / "ok.npy", npy_make<int16_t>(DType::I16, {2, 4, 8}, std::vector<int16_t>(64, 1)));
  r = test::run_gaia("decode " + q(p.dir / "ok.npy") + p.tokenizer() + " --decoder " + q(p.tok / "tokenizer.safetensors") +
                     p.tiny() + " --out " + q(p.dir / "x.mp4"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("not a gaia video decoder"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "x.mp4"));
}

// decoder.train_max_time: every training step's noise level (metrics.jsonl "t") is drawn below it; the default
// draws from all of [0, 1]; out of range is one error naming the key.
TEST(DecoderCli, TrainDrawsNoiseLevelsBelowTrainMaxTime) {
  auto& p = DecoderPipeline::get();
  const std::string base = "decoder train " + q(p.ds) + p.tokenizer() + p.tiny() + " --val-every 100 --steps 8";
  auto times = [](const fs::path& metrics) { return test::jsonl_numbers(metrics, "t"); };
  auto r = test::run_gaia(base + " --set decoder.train_max_time=0.3 --out " + q(p.dir / "tmax"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto low = times(p.dir / "tmax" / "metrics.jsonl");
  ASSERT_EQ(low.size(), 8u);
  for (double t : low) {
    EXPECT_GE(t, 0.0);
    EXPECT_LE(t, 0.3);
  }
  r = test::run_gaia(base + " --out " + q(p.dir / "tfull"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto full = times(p.dir / "tfull" / "metrics.jsonl");
  ASSERT_EQ(full.size(), 8u);
  EXPECT_GT(*std::max_element(full.begin(), full.end()), 0.3);  // same seed, same draws, scaled by 1 / 0.3
  for (size_t i = 0; i < full.size(); ++i) EXPECT_NEAR(low[i], 0.3 * full[i], 1e-9) << i;
  r = test::run_gaia(base + " --set decoder.train_max_time=0 --out " + q(p.dir / "tbad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("decoder.train_max_time"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "tbad" / "metrics.jsonl"));
}

// Fine-tuning (--init): with a zero learning rate the run keeps the given weights (up to the EMA's rounding), and
// temporal attention layers they lack start as identities; a file that is not a video decoder is one clear error.
TEST(DecoderCli, InitStartsFromTheGivenWeights) {
  auto& p = DecoderPipeline::get();
  const std::string base = "decoder train " + q(p.ds) + p.tokenizer() + p.tiny() + " --val-every 100";
  auto r = test::run_gaia(base + " --steps 2 --out " + q(p.dir / "init-base"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto init = p.dir / "init-base" / "decoder.safetensors";
  r = test::run_gaia(base + " --steps 2 --seed 7 --set decoder.lr=0 --set decoder.final_lr=0 --init " + q(init) +
                     " --out " + q(p.dir / "init-tuned"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("initialised from"), std::string::npos) << r.output;
  SafetensorsFile a(init), b(p.dir / "init-tuned" / "decoder.safetensors");
  ASSERT_EQ(a.names(), b.names());
  for (const auto& n : a.names())
    ASSERT_TRUE(torch::allclose(tensor_from_view(a.get(n)), tensor_from_view(b.get(n)), 1e-5, 1e-6)) << n;
  // Without --init the other seed gives other weights: the comparison above is not vacuous.
  r = test::run_gaia(base + " --steps 2 --seed 7 --set decoder.lr=0 --set decoder.final_lr=0 --out " +
                     q(p.dir / "init-fresh"));
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile c(p.dir / "init-fresh" / "decoder.safetensors");
  bool differs = false;
  for (const auto& n : a.names())
    differs = differs || !torch::allclose(tensor_from_view(a.get(n)), tensor_from_view(c.get(n)), 1e-3, 1e-3);
  EXPECT_TRUE(differs);
  // Temporal attention the --init weights lack (tiny has it at levels 0 and 1; here the init has it at level 1 only)
  // starts as the identity: at learning rate 0 the grown network predicts exactly what the given one does.
  r = test::run_gaia(base + " --steps 2 --set decoder.temporal_levels=[1] --out " + q(p.dir / "init-t1"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(base + " --steps 2 --set decoder.lr=0 --set decoder.final_lr=0 --init " +
                     q(p.dir / "init-t1" / "decoder.safetensors") + " --out " + q(p.dir / "init-t01"));
  ASSERT_EQ(r.status, 0) << r.output;
  {
    auto small = decoder::load_decoder(p.dir / "init-t1" / "decoder.safetensors", torch::kCPU);
    auto grown = decoder::load_decoder(p.dir / "init-t01" / "decoder.safetensors", torch::kCPU);
    EXPECT_EQ(grown->cfg.temporal_levels, (std::vector<int>{0, 1}));
    EXPECT_GT(grown->parameter_count(), small->parameter_count());
    torch::manual_seed(1);
    decoder::DenoiserInput in;
    in.x = torch::randn({1, 3, 3, 32, 64});
    in.context = torch::zeros({1, 3});
    in.tokens = torch::randint(0, small->K, {1, 3, 32 / small->D, 64 / small->D}, torch::kLong);
    if (small->cfg.cond_image) in.cond_image = torch::randn({1, 3, 3, 32, 64});
    in.time = torch::full({1, 3}, 0.5);
    in.rate = torch::zeros({1}, torch::kLong);
    torch::NoGradGuard ng;
    auto vs = small->forward(in), vg = grown->forward(in);
    EXPECT_GT(vs.abs().max().item<double>(), 1e-4);  // not trivially zero
    EXPECT_TRUE(torch::allclose(vg, vs, 1e-5, 1e-6));
  }
  r = test::run_gaia(base + " --steps 2 --init " + q(p.tok / "tokenizer.safetensors") + " --out " + q(p.dir / "init-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("not a gaia video decoder"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "init-bad" / "decoder.safetensors"));
}

// Decoding generated tokens (--world), the case the paper's video decoder exists for (§2.4). In-process, a generator
// that hands back the true tokens reproduces the true-token evaluation, so the generated path decodes what it is
// given and scores it the same way; the generator sees the clip's 6.25 Hz token frames and recorded actions. Then
// the CLI with a world model trained for two steps: reproducible, different from the true tokens, and bad inputs.
TEST(DecoderCli, EvalDecodesWorldModelRollouts) {
  auto& p = DecoderPipeline::get();
  auto r = test::run_gaia("decoder train " + q(p.ds) + p.tokenizer() + p.tiny() + " --val-every 100 --steps 2 --out " +
                          q(p.dir / "gen-dec"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto dec = p.dir / "gen-dec" / "decoder.safetensors";
  {
    Config dc;
    auto model = decoder::load_decoder(dec, torch::kCPU, &dc);
    auto tok = tokenizer::load_tokenizer(p.tok / "tokenizer.safetensors", torch::kCPU);
    decoder::DecoderEvalOptions o;
    o.clips = 2;
    o.token_frames = 3;
    o.steps = {2};
    auto truth = decoder::evaluate_decoder(dc, model, tok, p.ds, o);
    std::vector<torch::Tensor> seen_actions;
    o.generate = [&](const torch::Tensor& tokens, const torch::Tensor& actions) {
      EXPECT_EQ(tokens.sizes().vec(), (std::vector<int64_t>{3, 4, 8}));
      seen_actions.push_back(actions.clone());
      return tokens.clone();
    };
    auto same = decoder::evaluate_decoder(dc, model, tok, p.ds, o);
    ASSERT_EQ(seen_actions.size(), 2u);  // once per clip
    for (const auto& a : seen_actions) {
      ASSERT_EQ(a.sizes().vec(), (std::vector<int64_t>{3, 2}));
      EXPECT_TRUE(torch::isfinite(a).all().item<bool>());
      EXPECT_GT(a.select(1, 0).min().item<double>(), 0.0);  // m/s, not normalised: the synth drives move
    }
    EXPECT_EQ(same["tokens"], "generated");
    EXPECT_EQ(truth["tokens"], "true");
    EXPECT_FALSE(same.contains("tokenizer_decoder"));  // no 25 Hz tokens of its own for generated frames
    for (const char* k : {"psnr_6.25hz", "psnr_25hz", "flicker_6.25hz", "flicker_25hz"}) {
      EXPECT_NEAR(same["tokenizer_decoder_blended"][k].get<double>(), truth["tokenizer_decoder_blended"][k].get<double>(),
                  1e-3) << k;
      EXPECT_NEAR(same["video_decoder"]["2"][k].get<double>(), truth["video_decoder"]["2"][k].get<double>(), 1e-3) << k;
    }
    // Per-clip flicker, whose mean is the reported flicker.
    const auto per = same["video_decoder"]["2"]["flicker_6.25hz_per_clip"].get<std::vector<double>>();
    ASSERT_EQ(per.size(), 2u);
    EXPECT_NEAR((per[0] + per[1]) / 2, same["video_decoder"]["2"]["flicker_6.25hz"].get<double>(), 1e-9);
    o.generate = [](const torch::Tensor& tokens, const torch::Tensor&) { return tokens.slice(0, 1); };
    try {
      decoder::evaluate_decoder(dc, model, tok, p.ds, o);
      ADD_FAILURE() << "a generator of the wrong shape was accepted";
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find("token generator gave [2, 4, 8]"), std::string::npos) << e.what();
    }
  }
  r = test::run_gaia("tokenize " + q(p.ds) + p.tokenizer() + p.tiny() + " --out " + q(p.dir / "gen-tokens"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("world train " + q(p.dir / "gen-tokens") + p.tiny() + " --steps 2 --val-every 2 --out " +
                     q(p.dir / "gen-world"));
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string base = "decoder eval " + q(p.ds) + p.tokenizer() + " --decoder " + q(dec) +
                           " --clips 2 --token-frames 3 --steps 2" + p.tiny();
  const std::string world = " --world " + q(p.dir / "gen-world" / "world.safetensors");
  r = test::run_gaia(base + " --out " + q(p.dir / "gen-eval-true"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(base + world + " --prompt-frames 1 --out " + q(p.dir / "gen-eval"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(base + world + " --prompt-frames 1 --out " + q(p.dir / "gen-eval-again"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto t = nlohmann::json::parse(read_file(p.dir / "gen-eval-true" / "eval.json"));
  auto g = nlohmann::json::parse(read_file(p.dir / "gen-eval" / "eval.json"));
  auto g2 = nlohmann::json::parse(read_file(p.dir / "gen-eval-again" / "eval.json"));
  EXPECT_EQ(g["world"]["prompt_frames"].get<int>(), 1);
  EXPECT_EQ(g["tokens"], "generated");
  // The same rollouts on every run (seeded per clip); not the true tokens (a two-step world model draws others).
  EXPECT_EQ(g["tokenizer_decoder_blended"]["flicker_6.25hz_per_clip"], g2["tokenizer_decoder_blended"]["flicker_6.25hz_per_clip"]);
  EXPECT_NE(g["tokenizer_decoder_blended"]["psnr_6.25hz"].get<double>(), t["tokenizer_decoder_blended"]["psnr_6.25hz"].get<double>());
  EXPECT_EQ(g["ground_truth"], t["ground_truth"]);  // the same clips
  // Bad inputs: one clear line each, no eval.json.
  r = test::run_gaia(base + world + " --prompt-frames 3 --out " + q(p.dir / "gen-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--prompt-frames must be in [1, --token-frames - 1] = [1, 2], got 3"), std::string::npos) << r.output;
  r = test::run_gaia(base + world + " --prompt-frames 1 --token-fps 25 --out " + q(p.dir / "gen-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--token-fps must be 6.25"), std::string::npos) << r.output;
  r = test::run_gaia(base + " --prompt-frames 2 --out " + q(p.dir / "gen-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--world"), std::string::npos) << r.output;
  r = test::run_gaia(base + " --world " + q(dec) + " --prompt-frames 1 --out " + q(p.dir / "gen-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find(dec.filename().string()), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "gen-bad" / "eval.json"));
}
