// World-model data (§2.1, §2.3, §4.2): the word vocabulary, token datasets (directories and bare .npy arrays),
// windows, balanced sampling, conditioning modes, batches, and the split that `gaia tokenize` carries over.
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <tuple>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/core/error.h"
#include "gaia/core/fs.h"
#include "gaia/core/npy.h"
#include "gaia/data/geofence.h"
#include "gaia/text/vocab.h"
#include "gaia/tokenizer/io.h"
#include "gaia/tokenizer/tokenize.h"
#include "gaia/world/batch.h"
#include "gaia/world/evaluate.h"
#include "gaia/world/model.h"
#include "gaia/world/token_dataset.h"
#include "test_util.h"
#include "token_fixture.h"

using namespace gaia;
using gaia::text::Vocab;
using gaia::world::Conditioning;
using gaia::world::ConditioningMix;
using gaia::world::TokenDataset;
using gaia::world::WindowSampler;
using gaia::world::WorldBatch;
using nlohmann::json;
using namespace gaia::test::token_fixture;

namespace {

// Three episodes of 8, 3 and 10 steps; e0 has a missing speed at step 2 and missing actions at step 5.
fs::path make_small(const test::TempDir& dir) {
  fs::path root = dir / "tokens";
  write_header(root);
  EpisodeSpec a{"e0", 8, "clear", 0};
  a.action = [](int64_t t) {
    if (t == 2) return std::make_pair(kNaN, 0.004f);
    if (t == 5) return std::make_pair(kNaN, kNaN);
    return std::make_pair(float(t), -0.01f);
  };
  write_episode(root, a);
  write_episode(root, EpisodeSpec{"e1", 3, "rain", 5});
  write_episode(root, EpisodeSpec{"e2", 10, "fog", 9});
  return root;
}

bool same(const torch::Tensor& a, const torch::Tensor& b) {
  if (a.defined() != b.defined()) return false;
  if (!a.defined()) return true;
  if (a.is_floating_point()) return torch::equal(torch::nan_to_num(a, -123.0), torch::nan_to_num(b, -123.0));
  return torch::equal(a, b);
}

bool same(const WorldBatch& a, const WorldBatch& b) {
  return same(a.tokens, b.tokens) && same(a.actions, b.actions) && same(a.text_ids, b.text_ids) &&
         same(a.use_action, b.use_action) && same(a.use_text, b.use_text);
}

}  // namespace

// ---------------------------------------------------------------------------------------------------- Vocab

TEST(Vocab, WordsAreLowerCaseAndSplitOnNonAlphanumerics) {
  EXPECT_EQ(Vocab::words("Turn LEFT, at the 2nd light!  (café)"),
            (std::vector<std::string>{"turn", "left", "at", "the", "2nd", "light", "café"}));
  EXPECT_TRUE(Vocab::words(" ,.;- ").empty());
}

TEST(Vocab, BuildIsDeterministicFrequencyThenWord) {
  std::vector<std::string> caps{"red light ahead", "Red car, red light", "a bus", "the bus stops", "zebra"};
  Vocab v = Vocab::build(caps, 100);
  // red x3; bus, light x2; then the words seen once, alphabetically.
  std::vector<std::string> want{"<pad>", "<unk>", "red", "bus", "light", "a", "ahead", "car", "stops", "the", "zebra"};
  ASSERT_EQ(v.size(), static_cast<int64_t>(want.size()));
  for (size_t i = 0; i < want.size(); ++i) EXPECT_EQ(v.word(static_cast<int64_t>(i)), want[i]) << i;
  // Caption order does not matter; the size limit keeps the most frequent words (ids 0, 1 included).
  std::vector<std::string> rev(caps.rbegin(), caps.rend());
  EXPECT_TRUE(Vocab::build(rev, 100) == v);
  Vocab small = Vocab::build(caps, 4);
  EXPECT_EQ(small.size(), 4);
  EXPECT_EQ(small.word(3), "bus");
  EXPECT_EQ(small.id("light"), Vocab::kUnknown);
  EXPECT_NE(test::error_of([&] { Vocab::build(caps, 1); }).find("vocabulary size"), std::string::npos);
}

TEST(Vocab, EncodeGivesExactlyMIds) {
  Vocab v = Vocab::build({"red light ahead", "red car"}, 100);
  auto ids = v.encode("RED light, purple", 5);
  EXPECT_EQ(ids, (std::vector<int64_t>{v.id("red"), v.id("light"), Vocab::kUnknown, Vocab::kPad, Vocab::kPad}));
  EXPECT_EQ(v.encode("red red red light ahead car", 3), (std::vector<int64_t>{v.id("red"), v.id("red"), v.id("red")}));
  EXPECT_EQ(v.encode("", 2), (std::vector<int64_t>{0, 0}));
}

TEST(Vocab, JsonRoundTripAndErrors) {
  Vocab v = Vocab::build({"left turn at the lights", "right turn"}, 50);
  std::string stored = v.to_json().dump();  // as a string, the way safetensors metadata holds it
  Vocab back = Vocab::from_json(json::parse(stored), "model.safetensors");
  EXPECT_TRUE(back == v);
  EXPECT_EQ(back.encode("turn left", 4), v.encode("turn left", 4));
  json bad = v.to_json();
  bad["words"][0] = "hello";
  EXPECT_NE(test::error_of([&] { Vocab::from_json(bad, "model.safetensors"); }).find("model.safetensors"), std::string::npos);
  bad = v.to_json();
  bad["words"].push_back("turn");
  EXPECT_NE(test::error_of([&] { Vocab::from_json(bad, "m"); }).find("twice"), std::string::npos);
  EXPECT_NE(test::error_of([&] { Vocab::from_json(json{{"format", "gaia-vocab"}}, "m"); }).find("m: bad vocabulary"), std::string::npos);
}

// ------------------------------------------------------------------------------------------- TokenDataset

TEST(WorldData, OpensDirectoryWithShapesAndMetadata) {
  test::TempDir dir;
  TokenDataset ds(make_small(dir));
  EXPECT_FALSE(ds.bare());
  EXPECT_EQ(ds.grid_h(), kH);
  EXPECT_EQ(ds.grid_w(), kW);
  EXPECT_EQ(ds.tokens_per_step(), kN);
  EXPECT_EQ(ds.codebook_size(), kK);
  EXPECT_DOUBLE_EQ(ds.rate_hz(), 6.25);
  EXPECT_TRUE(ds.has_captions());
  ASSERT_EQ(ds.ids(), (std::vector<std::string>{"e0", "e1", "e2"}));
  EXPECT_EQ(ds.steps(0), 8);
  EXPECT_EQ(ds.steps(1), 3);
  EXPECT_EQ(ds.meta(1).weather, "rain");
  EXPECT_TRUE(std::isnan(ds.actions(0)[2 * 2]));
  auto ep = ds.episode(2);
  ASSERT_EQ(ep->tokens.size(), static_cast<size_t>(10 * kN));
  EXPECT_EQ(ep->tokens[static_cast<size_t>(7 * kN + 4)], token_at(9, 7, 4));
  EXPECT_EQ(ep->captions[3], caption_at("fog", 3));
  EXPECT_EQ(ds.episode(2), ep);  // cached: the same object
  ds.check_all();
  // A stated codebook size must match the dataset's.
  std::string err = test::error_of([&] { TokenDataset(dir / "tokens", 32); });
  EXPECT_NE(err.find("dataset.json"), std::string::npos) << err;
}

TEST(WorldData, BatchHasTokensNormalisedActionsAndText) {
  test::TempDir dir;
  TokenDataset ds(make_small(dir));
  Vocab v = world::build_vocab(ds, {0, 1, 2}, 64);
  EXPECT_EQ(v.id("a"), 2);  // "a", "road", "step" are in every caption; ties go alphabetically
  EXPECT_EQ(v.id("step"), 4);
  std::vector<world::Window> ws{{0, 1, 4}, {2, 6, 4}};
  std::mt19937_64 rng(7);
  WorldBatch b = ds.make_batch(ws, &v, 3, ConditioningMix{}, rng);
  EXPECT_EQ(b.tokens.sizes(), (std::vector<int64_t>{2, 4, kN}));
  EXPECT_EQ(b.tokens.scalar_type(), torch::kInt64);
  EXPECT_EQ(b.actions.sizes(), (std::vector<int64_t>{2, 4, 2}));
  EXPECT_EQ(b.actions.scalar_type(), torch::kFloat32);
  EXPECT_EQ(b.text_ids.sizes(), (std::vector<int64_t>{2, 4, 3}));
  EXPECT_EQ(b.use_action.sizes(), (std::vector<int64_t>{2}));
  EXPECT_EQ(b.use_text.scalar_type(), torch::kBool);
  EXPECT_FALSE(b.text_emb.defined());
  for (int64_t t = 0; t < 4; ++t)
    for (int64_t i = 0; i < kN; ++i) {
      EXPECT_EQ(b.tokens[0][t][i].item<int64_t>(), token_at(0, 1 + t, i));
      EXPECT_EQ(b.tokens[1][t][i].item<int64_t>(), token_at(9, 6 + t, i));
    }
  // Example 0 covers e0 steps 1..4: speed t, curvature -0.01, except step 2 (speed NaN, curvature 0.004).
  auto a = b.actions[0];
  EXPECT_FLOAT_EQ(a[0][0].item<float>(), 1.0f / world::kSpeedScale);
  EXPECT_FLOAT_EQ(a[0][1].item<float>(), -0.01f / world::kCurvatureScale);
  EXPECT_TRUE(std::isnan(a[1][0].item<float>()));
  EXPECT_NEAR(a[1][1].item<float>(), 0.004 / world::kCurvatureScale, 1e-6);
  EXPECT_FLOAT_EQ(a[3][0].item<float>(), 4.0f / world::kSpeedScale);
  // Example 1 covers e2 steps 6..9 with the default speed t and curvature 0.
  EXPECT_FLOAT_EQ(b.actions[1][2][0].item<float>(), 8.0f / world::kSpeedScale);
  // Text: "A fog road, step 8" -> the first 3 words.
  auto want = v.encode(caption_at("fog", 8), 3);
  for (int64_t j = 0; j < 3; ++j) EXPECT_EQ(b.text_ids[1][2][j].item<int64_t>(), want[static_cast<size_t>(j)]);
  // Without a vocabulary there is no text.
  EXPECT_FALSE(ds.make_batch(ws, nullptr, 3, ConditioningMix{}, rng).text_ids.defined());
  // Windows must fit their episode and share a length.
  EXPECT_NE(test::error_of([&] { ds.make_batch({{1, 0, 4}}, &v, 3, ConditioningMix{}, rng); }).find("outside episode"),
            std::string::npos);
  EXPECT_NE(test::error_of([&] { ds.make_batch({{0, 0, 4}, {0, 0, 3}}, &v, 3, ConditioningMix{}, rng); }).find("same length"),
            std::string::npos);
}

TEST(WorldData, TokenOutOfRangeIsAnErrorNamingTheFile) {
  test::TempDir dir;
  fs::path root = make_small(dir);
  fs::path bad = root / "episodes" / "e1" / "tokens.npy";
  std::vector<int16_t> t(static_cast<size_t>(3 * kN), 1);
  t[static_cast<size_t>(kN + 2)] = kK;  // step 1, position 2
  npy_write(bad, npy_make(DType::I16, {3, kH, kW}, t));
  TokenDataset ds(root);  // episodes are checked when loaded
  ds.episode(0);
  std::string err = test::error_of([&] { ds.episode(1); });
  EXPECT_NE(err.find(bad.string()), std::string::npos) << err;
  EXPECT_NE(err.find("step 1, position 2"), std::string::npos) << err;
  EXPECT_NE(err.find("[0, 16)"), std::string::npos) << err;
  EXPECT_NE(test::error_of([&] { ds.check_all(); }).find(bad.string()), std::string::npos);
  // Wrong shapes and dtypes name their files too.
  npy_write(bad, npy_make(DType::I16, {3, kW, kH}, t));
  err = test::error_of([&] { TokenDataset(root).episode(1); });
  EXPECT_NE(err.find(bad.string()), std::string::npos) << err;
  EXPECT_NE(err.find("want [3, 2, 3]"), std::string::npos) << err;
  npy_write(bad, npy_make(DType::F32, {3, kH, kW}, std::vector<float>(static_cast<size_t>(3 * kN), 0.0f)));
  EXPECT_NE(test::error_of([&] { TokenDataset(root).episode(1); }).find("dtype F32"), std::string::npos);
  fs::path acts = root / "episodes" / "e2" / "actions.npy";
  npy_write(acts, npy_make(DType::F32, {9, 2}, std::vector<float>(18, 0.0f)));
  err = test::error_of([&] { TokenDataset ds2(root); });
  EXPECT_NE(err.find(acts.string()), std::string::npos) << err;
  fs::remove(root / "dataset.json");
  EXPECT_NE(test::error_of([&] { TokenDataset ds3(root); }).find("no dataset.json"), std::string::npos);
}

TEST(WorldData, BareNpyIsOneDriveSplitInTimeWithoutActionsOrText) {
  TokenDataset fx(test::source_dir() / "tests" / "fixtures" / "tokens_6x8x16_int16.npy");
  EXPECT_TRUE(fx.bare());
  // Its last tenth (rounded, at least one step kept for training) is held out.
  EXPECT_EQ(fx.ids(), (std::vector<std::string>{"tokens_6x8x16_int16", "tokens_6x8x16_int16.held-out"}));
  EXPECT_EQ(fx.steps(0), 5);
  EXPECT_EQ(fx.steps(1), 1);
  EXPECT_EQ(fx.grid_h(), 8);
  EXPECT_EQ(fx.grid_w(), 16);

  test::TempDir dir;
  std::vector<int32_t> t;
  for (int64_t i = 0; i < 6 * kN; ++i) t.push_back(static_cast<int32_t>(i % 11));  // max 10 -> K = 11
  npy_write(dir / "z.npy", npy_make(DType::I32, {6, kH, kW}, t));
  TokenDataset ds(dir / "z.npy");
  EXPECT_EQ(ds.codebook_size(), 11);
  EXPECT_FALSE(ds.has_captions());
  EXPECT_EQ(TokenDataset(dir / "z.npy", 64).codebook_size(), 64);
  std::string err = test::error_of([&] { TokenDataset(dir / "z.npy", 8); });
  EXPECT_NE(err.find("z.npy"), std::string::npos) << err;
  auto split = ds.split();
  EXPECT_EQ(split.train, (std::vector<std::string>{"z"}));
  EXPECT_EQ(split.held_out(), (std::vector<std::string>{"z.held-out"}));
  EXPECT_EQ(ds.episode(1)->tokens.front(), 5 * kN % 11);  // the held-out step is the file's last
  Vocab v = Vocab::build({"anything"}, 10);
  std::mt19937_64 rng(1);
  WorldBatch b = ds.make_batch(ds.windows({0}, 4, 1), &v, 2, ConditioningMix{}, rng);
  EXPECT_EQ(b.tokens.sizes(), (std::vector<int64_t>{2, 4, kN}));
  EXPECT_EQ(b.tokens[1][0][0].item<int64_t>(), kN % 11);
  EXPECT_TRUE(torch::isnan(b.actions).all().item<bool>());
  EXPECT_FALSE(b.text_ids.defined());
  // Only [frames, h, w] arrays of integers are token arrays.
  npy_write(dir / "flat.npy", npy_make(DType::I32, {6 * kN}, t));
  EXPECT_NE(test::error_of([&] { TokenDataset(dir / "flat.npy"); }).find("[frames, h, w]"), std::string::npos);
}

TEST(WorldData, SplitFileOrSeededDefault) {
  test::TempDir dir;
  fs::path root = make_small(dir);
  TokenDataset ds(root);
  auto s = ds.split(0.1, 3);
  EXPECT_EQ(s.train.size() + s.val_random.size(), 3u);
  EXPECT_FALSE(s.val_random.empty());  // small datasets still get a validation episode
  EXPECT_EQ(ds.split(0.1, 3).to_json(), s.to_json());
  auto all = ds.indices(s.train);
  for (auto i : ds.indices(s.val_random)) EXPECT_EQ(std::find(all.begin(), all.end(), i), all.end());
  // The split.json of the dataset wins (as gaia tokenize copies it from the source).
  data::Split file{{"e0", "e2"}, {"e1"}, {}};
  write_file_atomic(root / "split.json", file.to_json().dump());
  auto f = ds.split(0.5, 99);
  EXPECT_EQ(f.train, file.train);
  EXPECT_EQ(f.val_geofence, file.val_geofence);
  EXPECT_EQ(ds.indices(f.val_geofence), (std::vector<size_t>{1}));
  std::string err = test::error_of([&] { ds.indices({"e0", "e9"}); });
  EXPECT_NE(err.find("split.json"), std::string::npos) << err;
  EXPECT_NE(err.find("'e9'"), std::string::npos) << err;
  write_file_atomic(root / "split.json", "{\"train\": []}");
  EXPECT_NE(test::error_of([&] { ds.split(); }).find("split.json"), std::string::npos);
}

TEST(WorldData, WindowsNeverCrossEpisodes) {
  test::TempDir dir;
  TokenDataset ds(make_small(dir));  // 8, 3 and 10 steps
  auto ws = ds.windows({0, 1, 2}, 4, 2);
  // e0: starts 0, 2, 4; e1: none (3 < 4); e2: 0, 2, 4, 6.
  std::vector<world::Window> want{{0, 0, 4}, {0, 2, 4}, {0, 4, 4}, {2, 0, 4}, {2, 2, 4}, {2, 4, 4}, {2, 6, 4}};
  EXPECT_EQ(ws, want);
  for (auto& w : ds.windows({0, 1, 2}, 3, 1)) EXPECT_LE(w.start + w.steps, ds.steps(w.episode));
  EXPECT_EQ(ds.windows({0, 1, 2}, 3, 1).size(), 6u + 1u + 8u);
  EXPECT_TRUE(ds.windows({1}, 4, 1).empty());
  EXPECT_NE(test::error_of([&] { WindowSampler(ds, ds.windows({1}, 4, 1)); }).find("no windows"), std::string::npos);
  EXPECT_NE(test::error_of([&] { ds.windows({0}, 4, 0); }).find("stride"), std::string::npos);
}

// Stream windows score each frame of an episode once, the first window whole and each later one its last T/2 steps
// (with T/2 steps before them in view); capped, whole episodes give contiguous runs from their middle. score()
// counts only the scored steps, and a window's score is the mean cross-entropy of exactly those.
TEST(WorldData, StreamWindowsScoreEachFrameOnce) {
  test::TempDir dir;
  TokenDataset ds(make_small(dir));  // 8, 3 and 10 steps
  auto ws = world::stream_windows(ds, {0, 1, 2}, 4, 100);
  std::vector<world::Window> want{{0, 0, 4, 0}, {0, 2, 4, 2}, {0, 4, 4, 2}, {2, 0, 4, 0}, {2, 2, 4, 2}, {2, 4, 4, 2},
                                  {2, 6, 4, 2}};
  EXPECT_EQ(ws, want);
  for (size_t e : {size_t(0), size_t(2)}) {
    std::vector<int> times(size_t(ds.steps(e)), 0);
    for (auto& w : ws)
      if (w.episode == e)
        for (int64_t t = w.start + w.scored_from; t < w.start + w.steps; ++t) ++times[size_t(t)];
    for (int n : times) EXPECT_EQ(n, 1) << "episode " << e;
  }
  // Capped: one window per episode, scored whole; two per episode, contiguous from the middle.
  EXPECT_EQ(world::stream_windows(ds, {0, 2}, 4, 2), (std::vector<world::Window>{{0, 2, 4, 0}, {2, 2, 4, 0}}));
  EXPECT_EQ(world::stream_windows(ds, {0, 2}, 4, 5),
            (std::vector<world::Window>{{0, 0, 4, 0}, {0, 2, 4, 2}, {2, 2, 4, 0}, {2, 4, 4, 2}}));
  EXPECT_TRUE(world::stream_windows(ds, {1}, 4, 10).empty());
  auto keep = world::scored_steps(ws, 1, 2, 4, 1);  // windows 1, 2 from step 1: steps 2 and 3 scored
  EXPECT_TRUE(torch::equal(keep.squeeze(-1), torch::tensor({{0, 1, 1}, {0, 1, 1}}, torch::kBool)));

  Config c = test::config("tiny.yaml");
  ASSERT_EQ(c.world.context_steps, 4);
  torch::manual_seed(1);
  world::WorldModel m(c.world, kN, kK);
  const world::TextSource none(nullptr);
  world::ScoreOptions so;
  so.mode = Conditioning::kUnconditional;
  auto all = world::score(m, ds, ws, none, so);
  EXPECT_EQ(all.tokens, (8 + 10) * kN);
  auto one = world::score(m, ds, {ws[1]}, none, so);
  EXPECT_EQ(one.tokens, 2 * kN);
  torch::NoGradGuard ng;
  WorldBatch b = world::batch_at(ds, {ws[1]}, 0, 1, none, c.world.text_tokens, ConditioningMix{1, 0, 0});
  auto lp = torch::log_softmax(m->forward(b), -1).gather(-1, b.tokens.unsqueeze(-1));  // [1, 4, n, 1]
  EXPECT_NEAR(one.nats, -lp.slice(1, 2).mean().item<double>(), 1e-5);
}

TEST(WorldData, ConditioningModesFollowTheMix) {
  test::TempDir dir;
  TokenDataset ds(make_small(dir));
  Vocab v = world::build_vocab(ds, {0}, 32);
  std::vector<world::Window> ws(5000, world::Window{0, 0, 4});
  std::mt19937_64 rng(11);
  Config c;  // paper §4.2: 20 / 40 / 40
  WorldBatch b = ds.make_batch(ws, &v, 2, ConditioningMix::from(c.world), rng);
  auto ua = b.use_action, ut = b.use_text;
  EXPECT_EQ((ua & ut).sum().item<int64_t>(), 0);  // never both
  double n = 5000, action = ua.sum().item<int64_t>() / n, txt = ut.sum().item<int64_t>() / n;
  double uncond = 1 - action - txt;
  // Binomial standard deviation at p = 0.4, n = 5000 is 0.007: 0.03 is over four of them.
  EXPECT_NEAR(uncond, 0.2, 0.03);
  EXPECT_NEAR(action, 0.4, 0.03);
  EXPECT_NEAR(txt, 0.4, 0.03);
  // Degenerate mixes and bad ones.
  ConditioningMix only_text{0, 0, 1};
  for (int i = 0; i < 100; ++i) EXPECT_EQ(only_text.draw(rng), Conditioning::kText);
  EXPECT_NE(test::error_of([&] { ConditioningMix{0, 0, 0}.draw(rng); }).find("p_uncond"), std::string::npos);
}

TEST(WorldData, CounterfactualReplaysDrawTheirOwnActionShare) {
  test::TempDir dir;
  fs::path root = dir / "tokens";
  write_header(root);
  write_episode(root, EpisodeSpec{"e0", 8, "clear", 0});
  EpisodeSpec r{"e0-cf00", 8, "clear", 3};
  r.extra = {{data::kReplayOfKey, "e0"}};
  write_episode(root, r);
  TokenDataset ds(root);
  ASSERT_FALSE(ds.meta(0).is_replay());
  ASSERT_TRUE(ds.meta(1).is_replay());
  Vocab v = world::build_vocab(ds, {0}, 32);
  const int64_t n = 6000;
  auto shares = [&](size_t episode, const ConditioningMix& mix, uint64_t seed) {
    std::mt19937_64 rng(seed);
    WorldBatch b = ds.make_batch(std::vector<world::Window>(n, world::Window{episode, 0, 4}), &v, 2, mix, rng);
    EXPECT_EQ((b.use_action & b.use_text).sum().item<int64_t>(), 0);
    double a = b.use_action.sum().item<int64_t>() / double(n), t = b.use_text.sum().item<int64_t>() / double(n);
    return std::make_tuple(1 - a - t, a, t, b);
  };
  ConditioningMix mix{0.2, 0.4, 0.4, 0.8};
  // A replay: 80% action, the other 20% split 1 : 2 as p_uncond : p_text (5% / 15%). Binomial sd <= 0.0065.
  auto [u1, a1, t1, b1] = shares(1, mix, 5);
  EXPECT_NEAR(a1, 0.8, 0.025);
  EXPECT_NEAR(u1, 0.05, 0.02);
  EXPECT_NEAR(t1, 0.15, 0.02);
  // Any other episode keeps the paper's 20 / 40 / 40, with exactly the draws it had before replays had a mix.
  auto [u0, a0, t0, b0] = shares(0, mix, 5);
  EXPECT_NEAR(a0, 0.4, 0.025);
  EXPECT_NEAR(u0, 0.2, 0.025);
  auto [uu, au, tu, bu] = shares(0, ConditioningMix{0.2, 0.4, 0.4}, 5);
  EXPECT_TRUE(same(b0.use_action, bu.use_action) && same(b0.use_text, bu.use_text));
  // -1: a replay draws like every other window.
  auto [ur, ar, tr, br] = shares(1, ConditioningMix{0.2, 0.4, 0.4, -1}, 5);
  EXPECT_TRUE(same(br.use_action, bu.use_action) && same(br.use_text, bu.use_text));
  // All action, and a mix with no text or unconditional share left.
  std::mt19937_64 rng(3);
  for (int i = 0; i < 50; ++i) EXPECT_EQ((ConditioningMix{0.2, 0.4, 0.4, 1}.draw(rng, true)), Conditioning::kAction);
  for (int i = 0; i < 50; ++i) EXPECT_EQ((ConditioningMix{0, 1, 0, 0.3}.draw(rng, true)), Conditioning::kAction);
  EXPECT_NE(test::error_of([&] { ConditioningMix{0.2, 0.4, 0.4, 1.5}.draw(rng, true); }).find("p_action_replay"),
            std::string::npos);
}

TEST(WorldData, BalancingChangesTheDistributionAsTheBalancerSays) {
  test::TempDir dir;
  fs::path root = dir / "tokens";
  write_header(root);
  // 8 clear and 2 rainy episodes; in every episode the first 4 steps go straight, the last 4 turn left.
  for (int e = 0; e < 10; ++e) {
    EpisodeSpec s{fmt::format("ep{:02d}", e), 8, e < 8 ? "clear" : "rain", e};
    s.action = [](int64_t t) { return std::make_pair(5.0f, t < 4 ? 0.0f : 0.01f); };
    write_episode(root, s);
  }
  TokenDataset ds(root);
  std::vector<size_t> eps(10);
  for (size_t i = 0; i < 10; ++i) eps[i] = i;
  auto ws = ds.windows(eps, 4, 4);
  ASSERT_EQ(ws.size(), 20u);
  // Steering comes from the window's own actions, not the episode's.
  EXPECT_EQ(ds.features(ws[0]).cat.at("steering"), "straight");
  EXPECT_EQ(ds.features(ws[1]).cat.at("steering"), "left");
  EXPECT_EQ(ds.features(ws[1]).cat.at("weather"), "clear");
  EXPECT_DOUBLE_EQ(ds.features(ws[1]).num.at("speed"), 5.0);

  auto rain_fraction = [&](const WindowSampler& s) {
    std::mt19937_64 rng(5);
    int rain = 0, n = 4000;
    for (auto& w : s.sample(n, rng)) rain += ds.meta(w.episode).weather == "rain";
    return double(rain) / n;
  };
  WindowSampler uniform(ds, ws);
  EXPECT_FALSE(uniform.balanced());
  EXPECT_NEAR(rain_fraction(uniform), 0.2, 0.03);
  for (double ex : {0.5, 1.0}) {
    WindowSampler s(ds, ws, {"weather", "steering"}, ex, 10);
    auto h = s.balancer().histogram("weather", s.rows());
    double want = h.bins[0] == "rain" ? h.sampled[0] : h.sampled[1];
    // exponent 1: uniform (0.5); 0.5: sqrt(0.2) / (sqrt(0.2) + sqrt(0.8)) = 1/3
    EXPECT_NEAR(want, ex == 1.0 ? 0.5 : 1.0 / 3.0, 1e-9);
    EXPECT_NEAR(rain_fraction(s), want, 0.03) << ex;
  }
}

TEST(WorldData, TrainingBatchesAreAFunctionOfSeedAndStep) {
  test::TempDir dir;
  TokenDataset ds(make_small(dir));
  Config c = test::config("tiny.yaml");  // T = 4, m = 2, batch 4
  auto split = ds.split();
  Vocab v = world::build_vocab(ds, ds.indices(split.train), c.world.text_vocab);
  WindowSampler s(ds, ds.windows({0, 1, 2}, c.world.context_steps, 1), c.data.balance_world, c.data.balance_exponent,
                  c.data.balance_bins);
  WorldBatch a = world::training_batch(ds, s, &v, c.world, 1, 17);
  EXPECT_EQ(a.tokens.sizes(), (std::vector<int64_t>{4, 4, kN}));
  EXPECT_EQ(a.text_ids.size(2), 2);
  // A fresh dataset and sampler (as after a restart) give the same batch; other steps and seeds differ.
  TokenDataset ds2(dir / "tokens");
  WindowSampler s2(ds2, ds2.windows({0, 1, 2}, c.world.context_steps, 1), c.data.balance_world,
                   c.data.balance_exponent, c.data.balance_bins);
  EXPECT_TRUE(same(a, world::training_batch(ds2, s2, &v, c.world, 1, 17)));
  int differ_step = 0, differ_seed = 0;
  for (int k = 0; k < 5; ++k) {
    differ_step += !same(a, world::training_batch(ds, s, &v, c.world, 1, 18 + k));
    differ_seed += !same(a, world::training_batch(ds, s, &v, c.world, 2 + k, 17));
  }
  EXPECT_GE(differ_step, 4);
  EXPECT_GE(differ_seed, 4);
}

TEST(WorldData, BatchToAndSliceSteps) {
  test::TempDir dir;
  TokenDataset ds(make_small(dir));
  Vocab v = world::build_vocab(ds, {0}, 32);
  std::mt19937_64 rng(3);
  WorldBatch b = ds.make_batch({{0, 0, 6}, {2, 3, 6}}, &v, 2, ConditioningMix{}, rng);
  WorldBatch s = b.slice_steps(2, 5);
  EXPECT_EQ(s.steps(), 3);
  EXPECT_EQ(s.batch(), 2);
  EXPECT_TRUE(torch::equal(s.tokens[1][0], b.tokens[1][2]));
  EXPECT_TRUE(same(s.actions[0], b.actions[0].slice(0, 2, 5)));
  EXPECT_TRUE(torch::equal(s.text_ids, b.text_ids.slice(1, 2, 5)));
  EXPECT_TRUE(torch::equal(s.use_action, b.use_action));
  EXPECT_FALSE(s.text_emb.defined());
  EXPECT_NE(test::error_of([&] { b.slice_steps(4, 7); }).find("slice_steps"), std::string::npos);
  WorldBatch c = b.to(torch::kCPU);
  EXPECT_TRUE(same(b, c));
  EXPECT_FALSE(c.text_emb.defined());
}

// Other examples' captions for the same frames (--distill-other-text): example b of the first n gets example b+1's
// text (the last one the first's), text on and actions off; frames and actions stay the example's own.
TEST(WorldData, RolledTextGivesEachExampleTheNextOnesCaption) {
  test::TempDir dir;
  TokenDataset ds(make_small(dir));
  Vocab v = world::build_vocab(ds, {0}, 32);
  std::mt19937_64 rng(3);
  WorldBatch b = ds.make_batch({{0, 0, 6}, {2, 3, 6}, {0, 2, 6}}, &v, 2, ConditioningMix{}, rng);
  ASSERT_FALSE(torch::equal(b.text_ids[0], b.text_ids[1]));  // clear and fog: the roll is visible
  WorldBatch r = b.with_rolled_text(3);
  ASSERT_EQ(r.batch(), 3);
  for (int64_t i = 0; i < 3; ++i) {
    EXPECT_TRUE(torch::equal(r.tokens[i], b.tokens[i]));
    EXPECT_TRUE(same(r.actions[i], b.actions[i]));
    EXPECT_TRUE(torch::equal(r.text_ids[i], b.text_ids[(i + 1) % 3]));
  }
  EXPECT_TRUE(r.use_text.all().item<bool>());
  EXPECT_FALSE(r.use_action.any().item<bool>());
  WorldBatch h = b.with_rolled_text(2);  // the first two only, still rolled over the whole batch
  ASSERT_EQ(h.batch(), 2);
  EXPECT_TRUE(torch::equal(h.text_ids[1], b.text_ids[2]));
  EXPECT_NE(test::error_of([&] { b.with_rolled_text(4); }).find("with_rolled_text"), std::string::npos);
  WorldBatch bare = b;
  bare.text_ids = torch::Tensor();
  EXPECT_NE(test::error_of([&] { bare.with_rolled_text(1); }).find("no text"), std::string::npos);
}

TEST(WorldData, TokenizeCopiesTheSourceSplit) {
  test::TempDir dir;
  test::synth_dataset(dir / "ds", 3, 0.4);
  data::Dataset src(dir / "ds");
  data::Split split{{src.ids()[0], src.ids()[2]}, {src.ids()[1]}, {}};
  write_file_atomic(dir / "ds" / "split.json", split.to_json().dump());
  Config c = test::config("tiny.yaml");
  torch::manual_seed(0);
  tokenizer::ImageTokenizer t(c);  // untrained weights tokenize as well as any for this purpose
  tokenizer::save_tokenizer(t, c, dir / "tok.safetensors");
  tokenizer::tokenize_dataset(dir / "ds", dir / "tok.safetensors", dir / "tokens", 6.25, torch::kCPU);
  ASSERT_TRUE(fs::exists(dir / "tokens" / "split.json"));
  TokenDataset ds(dir / "tokens");
  EXPECT_EQ(ds.size(), 3u);
  EXPECT_EQ(ds.codebook_size(), c.tokenizer.codebook_size);
  auto got = ds.split();
  EXPECT_EQ(got.to_json(), split.to_json());
  EXPECT_EQ(ds.indices(got.val_geofence), (std::vector<size_t>{1}));
  ds.check_all();
  EXPECT_EQ(ds.steps(0), 3);  // 0.4 s at 25 Hz = 10 frames -> steps at 0, 0.16, 0.32 s
  // A broken source split stops tokenize with an error naming it.
  write_file_atomic(dir / "ds" / "split.json", "{\"train\": 3}");
  std::string err = test::error_of(
      [&] { tokenizer::tokenize_dataset(dir / "ds", dir / "tok.safetensors", dir / "tokens", 6.25, torch::kCPU); });
  EXPECT_NE(err.find((dir / "ds" / "split.json").string()), std::string::npos) << err;
}

// Steering sensitivity buckets each frame by the curvature of the step before it, and measures only what the
// curvature actions change: with the curvature projection's weight at zero the model cannot see the curvature, and
// zeroing or mirroring it changes nothing; with a weight it does.
TEST(WorldEval, SteeringSensitivityBucketsFramesByTheTurnBeforeThem) {
  test::TempDir dir;
  fs::path root = dir / "tokens";
  write_header(root);
  EpisodeSpec e{"e0", 12, "clear", 0};
  // left (+0.01), right (-0.01), straight (0.001), one missing curvature at step 6
  e.action = [](int64_t t) { return std::make_pair(5.0f, t == 6 ? kNaN : t % 3 == 0 ? 0.01f : t % 3 == 1 ? -0.01f : 0.001f); };
  write_episode(root, e);
  TokenDataset ds(root);
  Config c = test::config("tiny.yaml");  // T = 4
  auto windows = ds.windows({0}, c.world.context_steps, c.world.context_steps);  // steps 0-3, 4-7, 8-11
  ASSERT_EQ(windows.size(), 3u);
  torch::manual_seed(5);
  world::WorldModel m(c.world, kN, kK);
  {
    torch::NoGradGuard ng;
    m->curvature_proj->weight.zero_();
  }
  auto s = world::steering_sensitivity(m, ds, windows, 2);
  // Frames t = 1..3 of each window follow steps t - 1 = 0..2: window 0 -> steps 0, 1, 2 (left, right, straight),
  // window 1 -> steps 4, 5, 6 (right, straight, missing), window 2 -> steps 8, 9, 10 (straight, left, right).
  EXPECT_EQ(s.left.frames, 2);
  EXPECT_EQ(s.right.frames, 3);
  EXPECT_EQ(s.straight.frames, 3);
  for (const auto* r : {&s.left, &s.right, &s.straight}) {
    EXPECT_GT(r->nats, 0.0);
    EXPECT_NEAR(r->zeroed_rise, 0.0, 1e-9);
    EXPECT_NEAR(r->mirrored_rise, 0.0, 1e-9);
  }
  {
    torch::NoGradGuard ng;
    m->curvature_proj->weight.normal_(0, 5.0);
  }
  auto t = world::steering_sensitivity(m, ds, windows, 2);
  EXPECT_EQ(t.left.frames, 2);
  EXPECT_TRUE(std::isfinite(t.left.nats));
  EXPECT_GT(std::abs(t.left.mirrored_rise) + std::abs(t.right.mirrored_rise), 1e-4);
}

// A split.json written before replays and mirror images joined the dataset (train-all's manifest recipe tokenizes
// the counterfactual replays into a token set that carries the clips' split): each joins its source's list, and
// an episode of no named source stays out of both.
TEST(WorldData, EpisodesAddedAfterTheSplitGoWithTheirSource) {
  test::TempDir dir;
  write_file_atomic(dir.path / "split.json",
                    R"({"train": ["a", "a-mirror"], "val_geofence": [], "val_random": [], "val_named": ["b"]})");
  const auto s = data::load_or_default_split(dir.path, {"a", "a-mirror", "a-cf00", "a-cf00-mirror", "b", "b-cf01", "c"});
  EXPECT_EQ(s.train, (std::vector<std::string>{"a", "a-mirror", "a-cf00", "a-cf00-mirror"}));
  EXPECT_EQ(s.val_named, (std::vector<std::string>{"b", "b-cf01"}));
  EXPECT_TRUE(s.val_random.empty());
  EXPECT_TRUE(s.val_geofence.empty());
}

TEST(WorldData, DefaultSplitNeverHoldsOutEveryEpisode) {
  test::TempDir dir;
  // A draw that holds out everything (here forced by the fraction; with two drives it happens 1% of the time at
  // 0.1): the first drive trains, with its mirror image, and the rest stay held out.
  const auto s = data::load_or_default_split(dir.path, {"a", "a-mirror", "b"}, 0.999999, 0);
  EXPECT_EQ(s.train, (std::vector<std::string>{"a", "a-mirror"}));
  EXPECT_EQ(s.held_out(), (std::vector<std::string>{"b"}));
}
