// Tokenizer training end to end on tiny synthetic data: overfitting, exact resume, tokenize (plain and mirrored),
// and CLI errors.
#include <algorithm>
#include <set>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/core/error.h"
#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "gaia/data/frame_set.h"
#include "gaia/data/geofence.h"
#include "gaia/data/mirror.h"
#include "gaia/eval/metrics.h"
#include "gaia/sizing/sizing.h"
#include "gaia/tokenizer/augment.h"
#include "gaia/tokenizer/evaluate.h"
#include "gaia/tokenizer/io.h"
#include "gaia/tokenizer/tokenize.h"
#include "gaia/tokenizer/trainer.h"
#include "gaia/torch/tensor_io.h"
#include "test_util.h"

using namespace gaia;

namespace {

Config checkpointing_config() {
  Config c = test::config("tiny.yaml");
  c.run.checkpoint_every = 10;
  return c;
}

// A tiny synth dataset at the tiny config's 32x64.
void make_dataset(const fs::path& dir, int episodes, double seconds) { test::synth_dataset(dir, episodes, seconds); }

// A barely trained tiny tokenizer at RUN/tokenizer.safetensors: enough to test what consumes one.
void train_two_steps(const fs::path& dataset, const fs::path& run) {
  tokenizer::TrainOptions o;
  o.dataset = dataset;
  o.out = run;
  o.steps = 2;
  tokenizer::train_tokenizer(checkpointing_config(), o);
}

}  // namespace

TEST(TokenizerTrain, OverfitsAFewFramesToHighPsnr) {
  test::TempDir dir;
  make_dataset(dir / "ds", 2, 0.2);  // 2 x 5 frames; one episode trains, one validates -> train on 5 frames
  Config c = checkpointing_config();
  c.tokenizer.lr = 3e-3;
  c.tokenizer.final_lr = 3e-3;
  c.tokenizer.warmup_steps = 0;
  c.tokenizer.disc_start = 1000000;
  c.tokenizer.batch_size = 5;
  c.run.checkpoint_every = 1000;
  tokenizer::TrainOptions o;
  o.dataset = dir / "ds";
  o.out = dir / "run";
  o.steps = 150;
  o.val_every = 150;
  o.restart_every = 30;
  double first_l2 = -1, last_l2 = 0;
  auto r = tokenizer::train_tokenizer(c, o, [&](const tokenizer::StepLog& l) {
    if (first_l2 < 0) first_l2 = l.losses["l2"].get<double>();
    last_l2 = l.losses["l2"].get<double>();
  });
  EXPECT_EQ(r.final_step, 150);
  EXPECT_LT(last_l2, first_l2 * 0.1);
  // Reconstruct the training frames with the saved weights: high PSNR.
  auto t = tokenizer::load_tokenizer(dir / "run" / "tokenizer.safetensors", torch::kCPU);
  data::Dataset ds(dir / "ds");
  auto split = data::load_or_default_split(ds);
  data::Episode ep = ds.episode(data::episode_indices(ds, split.train)[0]);
  std::vector<cv::Mat> frames;
  for (int i = 0; i < ep.size(); ++i) frames.push_back(ep.frame_bgr(i));
  auto rec = tokenizer::decode_tokens(t, tokenizer::encode_frames(t, frames, torch::kCPU), torch::kCPU);
  double p = 0;
  for (size_t i = 0; i < frames.size(); ++i) p += eval::psnr(frames[i], rec[i]);
  EXPECT_GT(p / double(frames.size()), 24.0) << "mean PSNR " << p / double(frames.size());
  // Notes say plainly that the teacher losses are off.
  bool said = false;
  for (auto& n : r.notes) said = said || n.find("perceptual loss off") != std::string::npos;
  EXPECT_TRUE(said);
}

TEST(TokenizerTrain, ResumeIsExact) {
  test::TempDir dir;
  make_dataset(dir / "ds", 3, 0.4);
  Config c = checkpointing_config();
  c.tokenizer.disc_start = 6;  // the GAN path and its optimiser are part of the resumed state too
  tokenizer::TrainOptions o;
  o.dataset = dir / "ds";
  o.steps = 16;
  o.val_every = 100;
  o.restart_every = 5;
  o.out = dir / "straight";
  tokenizer::train_tokenizer(c, o);
  o.out = dir / "resumed";
  o.stop_after = 10;
  auto r1 = tokenizer::train_tokenizer(c, o);
  EXPECT_EQ(r1.final_step, 10);
  EXPECT_FALSE(fs::exists(dir / "resumed" / "tokenizer.safetensors"));
  o.stop_after = -1;
  auto r2 = tokenizer::train_tokenizer(c, o);
  EXPECT_TRUE(r2.resumed);
  EXPECT_EQ(r2.final_step, 16);
  SafetensorsFile a(dir / "straight" / "tokenizer.safetensors"), b(dir / "resumed" / "tokenizer.safetensors");
  ASSERT_EQ(a.names(), b.names());
  for (auto& n : a.names()) {
    auto ta = tensor_from_view(a.get(n)), tb = tensor_from_view(b.get(n));
    EXPECT_TRUE(torch::allclose(ta, tb, 1e-6, 1e-7)) << n;
  }
}

TEST(TokenizerTrain, InitFineTunesFromWeightsAndBalancesTheGanGradient) {
  test::TempDir dir;
  make_dataset(dir / "ds", 2, 0.4);
  Config c = checkpointing_config();
  c.tokenizer.disc_start = 0;
  tokenizer::TrainOptions o;
  o.dataset = dir / "ds";
  o.out = dir / "base";
  o.steps = 3;
  std::vector<double> weights;
  tokenizer::train_tokenizer(c, o, [&](const tokenizer::StepLog& l) { weights.push_back(l.losses["gan_weight"].get<double>()); });
  ASSERT_EQ(weights.size(), 3u);
  for (double w : weights) EXPECT_TRUE(std::isfinite(w) && w > 0 && w <= 1e4 * c.tokenizer.w_gan) << w;
  // With a zero learning rate, fine-tuning keeps the --init weights exactly.
  Config z = c;
  z.tokenizer.lr = 0;
  z.tokenizer.final_lr = 0;
  z.run.seed = 99;  // a different seed would give different fresh weights
  o.out = dir / "tuned";
  o.init = dir / "base" / "tokenizer.safetensors";
  o.steps = 1;
  auto r = tokenizer::train_tokenizer(z, o);
  bool said = false;
  for (auto& n : r.notes) said = said || n.find("initialised from") != std::string::npos;
  EXPECT_TRUE(said);
  SafetensorsFile a(dir / "base" / "tokenizer.safetensors"), b(dir / "tuned" / "tokenizer.safetensors");
  for (auto& n : a.names()) {
    if (n.find("codebook") != std::string::npos) continue;  // dead-code restarts may move codes
    EXPECT_TRUE(torch::equal(tensor_from_view(a.get(n)), tensor_from_view(b.get(n)))) << n;
  }
  // A different architecture is a clear error naming the file.
  Config wide = c;
  wide.tokenizer.channels *= 2;
  o.out = dir / "wide";
  std::string err = test::error_of([&] { tokenizer::train_tokenizer(wide, o); });
  EXPECT_NE(err.find("tokenizer.safetensors"), std::string::npos) << err;
  EXPECT_NE(err.find("shape"), std::string::npos) << err;
}

TEST(TokenizerTrain, DecoderOnlyGrowsRefineAndTokenBlocksAndKeepsEveryCode) {
  test::TempDir dir;
  make_dataset(dir / "ds", 2, 0.4);
  train_two_steps(dir / "ds", dir / "base");
  auto base = tokenizer::load_tokenizer(dir / "base" / "tokenizer.safetensors", torch::kCPU);
  Config g = checkpointing_config();
  g.tokenizer.refine_blocks = 2;
  g.tokenizer.token_blocks = 1;
  g.tokenizer.disc_start = 1000000;
  ASSERT_EQ(tokenizer::ImageTokenizer(g)->parameter_count(), sizing::tokenizer_params(g).total);
  tokenizer::TrainOptions o;
  o.dataset = dir / "ds";
  o.decoder_only = true;
  o.steps = 6;
  // Without weights to freeze there is nothing to decode: a clear error.
  o.out = dir / "none";
  std::string err = test::error_of([&] { tokenizer::train_tokenizer(g, o); });
  EXPECT_NE(err.find("--init"), std::string::npos) << err;

  data::Dataset ds(dir / "ds");
  data::Episode ep = ds.episode(0);
  std::vector<cv::Mat> frames;
  for (int i = 0; i < ep.size(); ++i) frames.push_back(ep.frame_bgr(i));
  auto base_codes = tokenizer::encode_frames(base, frames, torch::kCPU);
  auto base_rec = tokenizer::decode_tokens(base, base_codes, torch::kCPU);

  // Grown with a zero learning rate: the refinement and token blocks start as identities, so every output is unchanged.
  o.init = dir / "base" / "tokenizer.safetensors";
  Config z = g;
  z.tokenizer.lr = z.tokenizer.final_lr = 0;
  o.out = dir / "grown";
  o.steps = 1;
  tokenizer::train_tokenizer(z, o);
  Config loaded;
  auto grown = tokenizer::load_tokenizer(dir / "grown" / "tokenizer.safetensors", torch::kCPU, &loaded);
  EXPECT_EQ(loaded.tokenizer.refine_blocks, 2);  // the architecture travels in the weights' metadata
  EXPECT_EQ(loaded.tokenizer.token_blocks, 1);
  auto grown_rec = tokenizer::decode_tokens(grown, base_codes, torch::kCPU);
  for (size_t i = 0; i < frames.size(); ++i) EXPECT_EQ(cv::norm(base_rec[i], grown_rec[i], cv::NORM_INF), 0) << i;

  // Trained: the decoder moves, the encoder and codebook do not move by a bit, and every frame keeps its codes.
  g.tokenizer.lr = g.tokenizer.final_lr = 2e-3;
  o.out = dir / "refined";
  o.steps = 6;
  o.restart_every = 2;  // dead-code restarts would move the codebook; decoder-only skips them
  auto r = tokenizer::train_tokenizer(g, o);
  EXPECT_EQ(r.final_step, 6);
  SafetensorsFile a(dir / "base" / "tokenizer.safetensors"), b(dir / "refined" / "tokenizer.safetensors");
  int moved = 0;
  for (auto& n : b.names()) {
    if (n.rfind("decoder.", 0) == 0) {
      moved += !a.contains(n) || !torch::equal(tensor_from_view(a.get(n)), tensor_from_view(b.get(n)));
      continue;
    }
    ASSERT_TRUE(a.contains(n)) << n;
    EXPECT_TRUE(torch::equal(tensor_from_view(a.get(n)), tensor_from_view(b.get(n)))) << n;
  }
  EXPECT_GT(moved, 10);
  EXPECT_GT(tensor_from_view(b.get("decoder.token.0.conv2.weight")).abs().max().item<float>(), 0)
      << "the token blocks train away from the identity";
  auto refined = tokenizer::load_tokenizer(dir / "refined" / "tokenizer.safetensors", torch::kCPU);
  EXPECT_TRUE(torch::equal(tokenizer::encode_frames(refined, frames, torch::kCPU), base_codes));
}

TEST(TokenizerTrain, EmaAveragesTheDecoderResumesExactlyAndKeepsTheCodes) {
  test::TempDir dir;
  make_dataset(dir / "ds", 2, 0.4);
  train_two_steps(dir / "ds", dir / "base");
  Config g = checkpointing_config();
  g.tokenizer.disc_start = 1000000;
  g.tokenizer.ema_decay = 0.9;
  g.tokenizer.lr = g.tokenizer.final_lr = 2e-3;
  tokenizer::TrainOptions o;
  o.dataset = dir / "ds";
  o.init = dir / "base" / "tokenizer.safetensors";
  o.decoder_only = true;
  o.val_every = 100;

  // One step: the warm-up decay is min(0.9, 1/10), so the saved decoder is 0.1 x the initial weights + 0.9 x the
  // trained ones (the checkpoint's model), and everything else is the trained model's.
  o.steps = 1;
  o.out = dir / "one";
  tokenizer::train_tokenizer(g, o);
  SafetensorsFile init(dir / "base" / "tokenizer.safetensors"), raw(dir / "one" / "checkpoint" / "tokenizer.safetensors"),
      saved(dir / "one" / "tokenizer.safetensors");
  int averaged = 0;
  for (auto& n : saved.names()) {
    auto s = tensor_from_view(saved.get(n)), r = tensor_from_view(raw.get(n));
    if (n.rfind("decoder.", 0) == 0) {
      auto expect = 0.1 * tensor_from_view(init.get(n)) + 0.9 * r;
      EXPECT_TRUE(torch::allclose(s, expect, 1e-5, 1e-6)) << n;
      averaged += !torch::equal(s, r);
    } else {
      EXPECT_TRUE(torch::equal(s, r)) << n;
      EXPECT_TRUE(torch::equal(s, tensor_from_view(init.get(n)))) << n;  // decoder-only: the codes stay
    }
  }
  EXPECT_GT(averaged, 10);

  // Stopped and resumed, the average comes back from the checkpoint: the same weights as one straight run.
  o.steps = 12;
  o.out = dir / "straight";
  tokenizer::train_tokenizer(g, o);
  o.out = dir / "resumed";
  o.stop_after = 7;
  tokenizer::train_tokenizer(g, o);
  o.stop_after = -1;
  EXPECT_TRUE(tokenizer::train_tokenizer(g, o).resumed);
  SafetensorsFile a(dir / "straight" / "tokenizer.safetensors"), b(dir / "resumed" / "tokenizer.safetensors");
  ASSERT_EQ(a.names(), b.names());
  for (auto& n : a.names())
    EXPECT_TRUE(torch::allclose(tensor_from_view(a.get(n)), tensor_from_view(b.get(n)), 1e-6, 1e-7)) << n;

  // Checkpointed without the average (ema_decay = 0) and resumed with it: the average starts from the resumed
  // weights (said in a note), is checkpointed from then on, and the run ends with an averaged decoder.
  Config plain = g;
  plain.tokenizer.ema_decay = 0;
  o.out = dir / "late";
  o.stop_after = 7;
  tokenizer::train_tokenizer(plain, o);
  EXPECT_FALSE(fs::exists(dir / "late" / "checkpoint" / "ema.safetensors"));
  o.stop_after = -1;
  std::string notes;
  auto late = tokenizer::train_tokenizer(g, o, {}, [&](const std::string& n) { notes += n + "\n"; });
  EXPECT_TRUE(late.resumed);
  EXPECT_NE(notes.find("starts at step 7"), std::string::npos) << notes;
  EXPECT_TRUE(fs::exists(dir / "late" / "checkpoint" / "ema.safetensors"));
  SafetensorsFile raw_late(dir / "late" / "checkpoint" / "tokenizer.safetensors"), saved_late(dir / "late" / "tokenizer.safetensors");
  int differ = 0;
  for (auto& n : saved_late.names())
    if (n.rfind("decoder.", 0) == 0) differ += !torch::equal(tensor_from_view(saved_late.get(n)), tensor_from_view(raw_late.get(n)));
  EXPECT_GT(differ, 10);  // an average of steps 7..12, not the last step's weights
}

TEST(TokenizerTrainCli, TokenizeAlignsActionsAndResumes) {
  test::TempDir dir;
  make_dataset(dir / "ds", 2, 2.0);  // 50 frames at 25 Hz -> 13 steps at 6.25 Hz
  train_two_steps(dir / "ds", dir / "run");
  auto r = tokenizer::tokenize_dataset(dir / "ds", dir / "run" / "tokenizer.safetensors", dir / "tok", 6.25, torch::kCPU);
  EXPECT_EQ(r.episodes_written, 2);
  data::Dataset ds(dir / "ds");
  data::Episode ep = ds.episode(0);
  fs::path te = dir / "tok" / "episodes" / ds.ids()[0];
  NpyArray tokens = npy_read(te / "tokens.npy");
  EXPECT_EQ(tokens.dtype, DType::I16);
  EXPECT_EQ(tokens.shape, (std::vector<int64_t>{13, 4, 8}));
  for (auto v : tokens.to_int64()) ASSERT_TRUE(v >= 0 && v < 256);
  NpyArray actions = npy_read(te / "actions.npy");
  EXPECT_EQ(actions.shape, (std::vector<int64_t>{13, 2}));
  // step 2 covers source frames 8..11: speed is their mean
  double want = (ep.speed(8) + ep.speed(9) + ep.speed(10) + ep.speed(11)) / 4.0;
  EXPECT_NEAR(actions.as<float>()[2 * 2], want, 1e-4);
  // Tokens equal encoding the subsampled frames directly.
  auto t = tokenizer::load_tokenizer(dir / "run" / "tokenizer.safetensors", torch::kCPU);
  auto direct = tokenizer::encode_frames(t, {ep.frame_bgr(8)}, torch::kCPU);
  for (int i = 0; i < 32; ++i) EXPECT_EQ(tokens.to_int64()[static_cast<size_t>(2 * 32 + i)], direct.reshape({-1})[i].item<int64_t>());
  auto again = tokenizer::tokenize_dataset(dir / "ds", dir / "run" / "tokenizer.safetensors", dir / "tok", 6.25, torch::kCPU);
  EXPECT_EQ(again.episodes_skipped, 2);
  EXPECT_EQ(again.episodes_written, 0);
  // The CLI's --mirror reaches tokenize: a plain token directory refuses to be resumed in mirror image.
  auto m = test::run_gaia("tokenize '" + (dir / "ds").string() + "' --tokenizer '" +
                          (dir / "run" / "tokenizer.safetensors").string() + "' --mirror --out '" + (dir / "tok").string() + "'");
  EXPECT_NE(m.status, 0);
  EXPECT_NE(m.output.find("dataset.json: exists with a different tokenizer grid, codebook, rate or --mirror"),
            std::string::npos) << m.output;
  EXPECT_FALSE(fs::exists(dir / "tok" / "episodes" / (ds.ids()[0] + "-mirror")));
  // A torn header is one error line naming it, not a bare parser message; nothing is written.
  write_file_atomic(dir / "tok" / "dataset.json", "{\"grid\": [4,");
  auto torn = test::run_gaia("tokenize '" + (dir / "ds").string() + "' --tokenizer '" +
                             (dir / "run" / "tokenizer.safetensors").string() + "' --out '" + (dir / "tok").string() + "'");
  EXPECT_NE(torn.status, 0);
  EXPECT_NE(torn.output.find("tok/dataset.json: invalid JSON"), std::string::npos) << torn.output;
  EXPECT_EQ(read_file(dir / "tok" / "dataset.json"), "{\"grid\": [4,");
}

TEST(TokenizerEvalCli, HeldOutFramesSpreadOverEveryEpisodeAndGroupsAddUp) {
  test::TempDir dir;
  make_dataset(dir / "ds", 24, 0.4);  // 24 x 10 frames; the default split holds out ~10%
  data::Dataset ds(dir / "ds");
  const auto held = data::load_or_default_split(ds).held_out();
  ASSERT_GE(held.size(), 2u);
  // Spread: n frames reach every held-out episode and keep `margin` frames clear of each episode's end.
  auto set = data::held_out_frames(ds, 0, 3, int(held.size()) * 2);
  ASSERT_EQ(set.frames.size(), held.size() * 2);
  std::set<size_t> seen;
  for (const auto& f : set.frames) {
    seen.insert(f.episode);
    EXPECT_LT(f.frame + 3, set.episodes[f.episode]->size());
  }
  EXPECT_EQ(seen.size(), held.size());
  EXPECT_EQ(data::frame_set(ds, held, 0, 0).frames.size(), held.size() * 10);  // n <= 0: every frame

  // Per-group figures are the frame-weighted parts of the totals, and the totals are the plain PSNR of each frame.
  train_two_steps(dir / "ds", dir / "run");
  Config c;
  auto t = tokenizer::load_tokenizer(dir / "run" / "tokenizer.safetensors", torch::kCPU, &c);
  std::vector<cv::Mat> frames;
  std::vector<tokenizer::FrameTags> tags;
  std::set<std::string> weathers;
  auto all = data::held_out_frames(ds, 0, 0, 20);
  for (const auto& f : all.frames) {
    frames.push_back(all.episodes[f.episode]->frame_bgr(f.frame));
    tags.push_back({{"weather", all.episodes[f.episode]->meta().weather}, {"time_of_day", ""}});
    weathers.insert(all.episodes[f.episode]->meta().weather);
  }
  int64_t calls = 0;
  auto j = tokenizer::evaluate_reconstruction(t, c, frames, tags, torch::kCPU, [&](int64_t) { ++calls; });
  EXPECT_EQ(calls, 2);  // batches of 16
  EXPECT_EQ(j["frames"].get<int64_t>(), 20);
  auto rec = tokenizer::decode_tokens(t, tokenizer::encode_frames(t, frames, torch::kCPU), torch::kCPU);
  double direct = 0;
  for (size_t i = 0; i < frames.size(); ++i) direct += eval::psnr(frames[i], rec[i]);
  EXPECT_NEAR(j["psnr"].get<double>(), direct / 20, 1e-6);
  ASSERT_TRUE(j.contains("by_weather"));
  EXPECT_FALSE(j.contains("by_time_of_day"));  // empty values are not grouped
  int64_t n = 0;
  double weighted = 0;
  std::set<std::string> keys;
  for (auto& [w, g] : j["by_weather"].items()) {
    keys.insert(w);
    n += g["frames"].get<int64_t>();
    weighted += g["frames"].get<double>() * g["psnr"].get<double>();
  }
  EXPECT_EQ(keys, weathers);
  EXPECT_EQ(n, 20);
  EXPECT_NEAR(weighted / 20, j["psnr"].get<double>(), 1e-6);
  tags.pop_back();
  EXPECT_THROW(tokenizer::evaluate_reconstruction(t, c, frames, tags, torch::kCPU), Error);

  // The command: spread over the held-out episodes, grouped by weather and time of day, written to --out.
  auto r = test::run_gaia("tokenizer eval '" + (dir / "ds").string() + "' --tokenizer '" +
                          (dir / "run" / "tokenizer.safetensors").string() + "' --max-frames 12 --out '" +
                          (dir / "eval.json").string() + "'");
  ASSERT_EQ(r.status, 0) << r.output;
  auto e = nlohmann::json::parse(read_file(dir / "eval.json"));
  EXPECT_EQ(e["frames"].get<int64_t>(), 12);
  int64_t by_time = 0;
  for (auto& [k, g] : e["by_time_of_day"].items()) by_time += g["frames"].get<int64_t>();
  EXPECT_EQ(by_time, 12);
  EXPECT_EQ(e["by_weather"].size(), weathers.size());
  // Per clip: the median and the worst of the episodes' own means, by footage (these drives are all procedural).
  ASSERT_TRUE(e.contains("by_clip")) << e.dump();
  std::vector<std::pair<double, std::string>> per_episode;
  for (auto& [id, g] : e["by_episode"].items()) per_episode.push_back({g["psnr"].get<double>(), id});
  std::sort(per_episode.begin(), per_episode.end());
  ASSERT_GE(per_episode.size(), 2u);
  const auto& clips = e["by_clip"]["procedural"];
  EXPECT_EQ(clips["episodes"].get<size_t>(), per_episode.size());
  EXPECT_EQ(clips["worst_episode"].get<std::string>(), per_episode.front().second);
  EXPECT_DOUBLE_EQ(clips["worst_psnr"].get<double>(), per_episode.front().first);
  const size_t k = per_episode.size();
  const double median = k % 2 ? per_episode[k / 2].first : 0.5 * (per_episode[k / 2 - 1].first + per_episode[k / 2].first);
  EXPECT_DOUBLE_EQ(clips["median_psnr"].get<double>(), median);
  EXPECT_FALSE(e["by_clip"].contains("real"));
}

TEST(TokenizerTrainCli, BadInputsAreClearErrors) {
  test::TempDir dir;
  make_dataset(dir / "ds", 2, 0.2);
  auto r = test::run_gaia("tokenizer train '" + (dir / "ds").string() + "' --out '" + (dir / "run").string() + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("frames are 32x64, the config wants 72x128"), std::string::npos) << r.output;
  write_file_atomic(dir / "bad.safetensors", "garbage that is not safetensors at all");
  auto e = test::run_gaia("tokenizer eval '" + (dir / "ds").string() + "' --tokenizer '" + (dir / "bad.safetensors").string() + "'");
  EXPECT_NE(e.status, 0);
  EXPECT_NE(e.output.find("bad.safetensors"), std::string::npos) << e.output;
  SafetensorsWriter w;
  w.add_f32("x", {1}, {1.0f});
  w.write(dir / "notok.safetensors");
  auto n = test::run_gaia("tokenize '" + (dir / "ds").string() + "' --tokenizer '" + (dir / "notok.safetensors").string() + "' --out '" + (dir / "t").string() + "'");
  EXPECT_NE(n.status, 0);
  EXPECT_NE(n.output.find("not a gaia tokenizer"), std::string::npos) << n.output;
}

// Fine-tuning the shipped tokenizer without a config: its refinement and token blocks come from the weights instead
// of being dropped (the built-in defaults have none), and a --set still wins.
TEST(TokenizerTrainCli, InitKeepsTheArchitectureOfItsWeights) {
  test::TempDir dir;
  auto r = test::run_gaia("synth --episodes 2 --seconds 0.4 --seed 3 --out " + test::q(dir / "ds"));  // 72x128
  ASSERT_EQ(r.status, 0) << r.output;
  const fs::path shipped = test::source_dir() / "models" / "tokenizer.safetensors";
  r = test::run_gaia("tokenizer train " + test::q(dir / "ds") + " --init " + test::q(shipped) +
                     " --decoder-only --steps 1 --val-every 0 --threads 1 --out " + test::q(dir / "ft"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("tokenizer.refine_blocks=2, as the --init weights have it"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("dropped"), std::string::npos) << r.output;
  SafetensorsFile a(shipped), b(dir / "ft" / "tokenizer.safetensors");
  EXPECT_EQ(a.names(), b.names());
  r = test::run_gaia("tokenizer train " + test::q(dir / "ds") + " --init " + test::q(shipped) +
                     " --decoder-only --set tokenizer.token_blocks=0 --steps 1 --val-every 0 --threads 1 --out " +
                     test::q(dir / "ft0"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("dropped (first: 'decoder.token.0"), std::string::npos) << r.output;
}

TEST(TokenizerTrain, TokenizeMirrorAddsMirrorImagesThatSteerTheOtherWay) {
  test::TempDir dir;
  make_dataset(dir / "ds", 2, 1.0);
  train_two_steps(dir / "ds", dir / "run");
  const fs::path w = dir / "run" / "tokenizer.safetensors";
  auto r = tokenizer::tokenize_dataset(dir / "ds", w, dir / "tok", 6.25, torch::kCPU, {}, /*mirror=*/true);
  EXPECT_EQ(r.episodes_written, 4);
  data::Dataset ds(dir / "ds");
  data::Episode ep = ds.episode(0);
  const fs::path plain = dir / "tok" / "episodes" / ds.ids()[0], mirror = dir / "tok" / "episodes" / (ds.ids()[0] + "-mirror");
  ASSERT_TRUE(fs::exists(mirror / "episode.json"));
  // Curvature changes sign, speed stays.
  NpyArray pa = npy_read(plain / "actions.npy"), ma = npy_read(mirror / "actions.npy");
  ASSERT_EQ(pa.shape, ma.shape);
  const float *a = pa.as<float>(), *m = ma.as<float>();
  for (int64_t i = 0; i < pa.shape[0] * 2; i += 2) {
    EXPECT_EQ(m[i], a[i]);
    EXPECT_EQ(m[i + 1], -a[i + 1]);
  }
  // Tokens are the encoding of the flipped frame.
  auto t = tokenizer::load_tokenizer(w, torch::kCPU);
  cv::Mat flipped;
  cv::flip(ep.frame_bgr(4), flipped, 1);
  auto direct = tokenizer::encode_frames(t, {flipped}, torch::kCPU).reshape({-1});
  auto mt = npy_read(mirror / "tokens.npy").to_int64();
  for (int i = 0; i < 32; ++i) EXPECT_EQ(mt[static_cast<size_t>(32 + i)], direct[i].item<int64_t>());
  // Captions and labels are the mirror's; the metadata names the source.
  auto meta = nlohmann::json::parse(read_file(mirror / "episode.json"));
  EXPECT_EQ(meta["id"], ds.ids()[0] + "-mirror");
  EXPECT_EQ(meta["mirror_of"], ds.ids()[0]);
  auto lab = nlohmann::json::parse(read_file(mirror / "labels.jsonl").substr(0, read_file(mirror / "labels.jsonl").find('\n')));
  EXPECT_DOUBLE_EQ(lab["curvature"].get<double>(), -ep.labels(0)["curvature"].get<double>());
  auto cap = read_file(mirror / "captions.jsonl");
  EXPECT_EQ(cap.substr(0, cap.find('\n')), nlohmann::json(data::mirror_words(ep.caption(0))).dump());
  // Resume skips both; a plain run into the mirrored directory is refused.
  auto again = tokenizer::tokenize_dataset(dir / "ds", w, dir / "tok", 6.25, torch::kCPU, {}, true);
  EXPECT_EQ(again.episodes_skipped, 4);
  EXPECT_EQ(again.episodes_written, 0);
  EXPECT_THROW(tokenizer::tokenize_dataset(dir / "ds", w, dir / "tok", 6.25, torch::kCPU), Error);
}

// Darkening (tokenizer.augment_dark): a share of the frames, never brighter, drawn from torch's generator so that a
// seeded step repeats; share 0 leaves the batch as it is.
TEST(TokenizerAugment, DarkensAShareOfTheFramesAndNeverBrightens) {
  torch::manual_seed(3);
  auto x = torch::rand({400, 3, 8, 8}) * 2 - 1;
  EXPECT_TRUE(torch::equal(tokenizer::darken_some(x, 0.0), x));
  torch::manual_seed(5);
  auto y = tokenizer::darken_some(x, 0.25);
  torch::manual_seed(5);
  EXPECT_TRUE(torch::equal(tokenizer::darken_some(x, 0.25), y));  // the same draws
  EXPECT_TRUE((y <= x + 1e-6).all().item<bool>());
  EXPECT_GE(y.min().item<float>(), -1.0f);
  const auto changed = (y - x).abs().amax({1, 2, 3}) > 1e-6;  // [400]
  const double share = changed.to(torch::kFloat).mean().item<double>();
  EXPECT_NEAR(share, 0.25, 0.07);  // 400 draws: 3 standard deviations
  // A changed frame is gain * v^gamma with gamma in [1, 3], gain in [0.2, 1]: between the darkest and the lightest.
  auto v = (x + 1) / 2, w = (y + 1) / 2;
  auto m = changed.view({-1, 1, 1, 1}).expand_as(v);
  EXPECT_TRUE((w.masked_select(m) >= (0.2 * v.pow(3)).masked_select(m) - 1e-5).all().item<bool>());
  // Mid-grey darkens more, relatively, than a light: the lights of a night scene stay lights.
  auto flat = torch::full({200, 3, 2, 2}, 0.0);  // v = 0.5
  flat.slice(2, 0, 1).fill_(0.9);                // top row v = 0.95
  torch::manual_seed(7);
  auto d = (tokenizer::darken_some(flat, 1.0) + 1) / 2;
  auto top = d.select(2, 0).mean({1, 2}), bottom = d.select(2, 1).mean({1, 2});
  EXPECT_TRUE((top / 0.95 >= bottom / 0.5 - 1e-5).all().item<bool>());
  EXPECT_NEAR(bottom.mean().item<double>(), 0.6 * 0.375 / (2 * std::log(2.0)), 0.02);  // E[gain] E[0.5^gamma]
}
