// Text as the paper encodes it (§2.1): precomputed per-step text embeddings in a token dataset (docs/formats.md,
// "Text embeddings"), batches that carry them, a world model trained and scored on them, `gaia text embed`'s
// resumable cache, and prompts through the encoder a model was trained with.
#include <cmath>
#include <random>

#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "gaia/sim/session.h"
#include "gaia/text/t5.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/embed_captions.h"
#include "gaia/world/evaluate.h"
#include "gaia/world/io.h"
#include "gaia/world/prompt_text.h"
#include "gaia/world/text_embeddings.h"
#include "gaia/world/token_dataset.h"
#include "gaia/world/trainer.h"
#include "test_util.h"
#include "token_fixture.h"

using namespace gaia;
using namespace gaia::test::token_fixture;
using gaia::world::TextSource;
using gaia::world::TokenDataset;
using gaia::test::q;

namespace {

constexpr int64_t kM = 2, kDim = 5;  // configs/tiny.yaml has world.text_tokens = 2

// The embedding value of episode e, step t, token j, channel c; steps below 3 share one row (captions repeat).
float emb_at(int e, int64_t t, int64_t j, int64_t c) {
  const int64_t s = t < 3 ? 0 : t;
  return float(e) + 0.01f * float(s) + 0.1f * float(j) - 0.001f * float(c);
}

torch::Tensor episode_emb(int e, int64_t steps, int64_t m = kM, int64_t dim = kDim) {
  auto t = torch::empty({steps, m, dim});
  auto a = t.accessor<float, 3>();
  for (int64_t s = 0; s < steps; ++s)
    for (int64_t j = 0; j < m; ++j)
      for (int64_t c = 0; c < dim; ++c) a[s][j][c] = emb_at(e, s, j, c);
  return t;
}

// Two episodes (8 and 10 steps) with captions, each with text embeddings from the encoder "test-encoder".
fs::path make_embedded(const test::TempDir& dir) {
  const fs::path root = dir / "tokens";
  write_header(root);
  write_episode(root, EpisodeSpec{"e0", 8, "clear", 0});
  write_episode(root, EpisodeSpec{"e1", 10, "rain", 7});
  world::write_text_embeddings(root / "episodes" / "e0", episode_emb(0, 8));
  world::write_text_embeddings(root / "episodes" / "e1", episode_emb(1, 10));
  world::write_text_emb_info(root, {"test-encoder", kM, kDim});
  return root;
}

// A deterministic stand-in encoder: each caption's embedding is a function of its bytes; counts what it encodes.
class FakeEncoder : public text::TextEncoder {
 public:
  explicit FakeEncoder(std::string id, int64_t dim = kDim) : id_(std::move(id)), dim_(dim) {}
  torch::Tensor encode(const std::string& caption, int64_t m) override {
    ++calls;
    float h = 0;
    for (unsigned char ch : caption) h = std::fmod(h * 31.0f + float(ch), 97.0f);
    return torch::arange(m * dim_, torch::kFloat).view({m, dim_}) * 0.01f + h / 97.0f;
  }
  bool embeds() const override { return true; }
  std::string identity() const override { return id_; }
  int calls = 0;

 private:
  std::string id_;
  int64_t dim_;
};

Config tiny_config() {
  Config c = test::config("tiny.yaml");
  c.run.device = "cpu";
  return c;
}

world::WorldTrainResult train_tiny(const fs::path& tokens, const fs::path& out, int steps = 4) {
  world::WorldTrainOptions o;
  o.tokens = tokens;
  o.out = out;
  o.steps = steps;
  o.val_every = steps;
  return world::train_world(tiny_config(), o);
}

}  // namespace

TEST(TextEmbeddings, BatchesCarryTheDatasetsEmbeddings) {
  test::TempDir dir;
  const fs::path root = make_embedded(dir);
  TokenDataset ds(root);
  ASSERT_TRUE(ds.has_text_emb());
  EXPECT_EQ(ds.text_emb().encoder, "test-encoder");
  EXPECT_EQ(ds.text_emb().m, kM);
  EXPECT_EQ(ds.text_emb().dim, kDim);
  // Held once per distinct row: steps 0-2 share theirs.
  auto ep = ds.episode(0);
  EXPECT_EQ(ep->text_emb.rows.size(), size_t((8 - 2) * kM * kDim));
  ASSERT_EQ(ep->text_emb.index.size(), size_t(8));
  EXPECT_EQ(ep->text_emb.index[0], ep->text_emb.index[2]);
  EXPECT_NE(ep->text_emb.index[2], ep->text_emb.index[3]);

  std::mt19937_64 rng(1);
  const std::vector<world::Window> ws{{0, 1, 4}, {1, 5, 4}};
  auto b = ds.make_batch(ws, TextSource::precomputed(), kM, world::ConditioningMix{}, rng);
  ASSERT_TRUE(b.text_emb.defined());
  EXPECT_FALSE(b.text_ids.defined());
  ASSERT_EQ(b.text_emb.sizes(), (std::vector<int64_t>{2, 4, kM, kDim}));
  for (size_t i = 0; i < ws.size(); ++i)
    EXPECT_TRUE(torch::equal(b.text_emb[long(i)], episode_emb(int(ws[i].episode), 10).narrow(0, ws[i].start, 4)))
        << "window " << i;
  // The built-in words instead: ids, no embeddings; m must be the embeddings' own.
  auto vocab = world::build_vocab(ds, {0, 1}, 64);
  auto w = ds.make_batch(ws, &vocab, kM, world::ConditioningMix{}, rng);
  EXPECT_TRUE(w.text_ids.defined());
  EXPECT_FALSE(w.text_emb.defined());
  EXPECT_NE(test::error_of([&] { ds.make_batch(ws, TextSource::precomputed(), 3, world::ConditioningMix{}, rng); })
                .find("m = 2"),
            std::string::npos);
}

TEST(TextEmbeddings, BadFilesAreClearErrors) {
  test::TempDir dir;
  const fs::path root = make_embedded(dir);
  const fs::path e1 = root / "episodes" / "e1";
  // All or none.
  fs::rename(e1 / "text_emb.npy", dir / "kept.npy");
  EXPECT_NE(test::error_of([&] { TokenDataset ds(root); }).find((e1).string() + ": no text_emb.npy"), std::string::npos);
  // While gaia text embed writes, the dataset reads as having none.
  write_file_atomic(root / world::kTextEmbPartialFile, "{}");
  EXPECT_FALSE(TokenDataset(root).has_text_emb());
  fs::remove(root / world::kTextEmbPartialFile);
  // Wrong m, NaN: named when the episode is read.
  world::write_text_embeddings(e1, episode_emb(1, 10, kM + 1));
  EXPECT_NE(test::error_of([&] { TokenDataset(root).episode(1); }).find("text_emb.npy: shape [10, 3, 5], want [steps = 10, m = 2, dim = 5]"),
            std::string::npos);
  auto bad = episode_emb(1, 10);
  bad[4][1][2] = std::nanf("");
  world::write_text_embeddings(e1, bad);
  EXPECT_NE(test::error_of([&] { TokenDataset(root).episode(1); }).find("text_emb.npy: contains NaN"), std::string::npos);
  // The record: an unknown key, and a record without files.
  fs::remove(e1 / "text_emb.npy");
  save_tensors({{"text_emb", episode_emb(1, 10).to(torch::kHalf)}}, e1 / "text_emb.safetensors");
  EXPECT_NEAR(TokenDataset(root).episode(1)->text_emb.step(5)[1], emb_at(1, 5, 0, 1), 1e-3);  // F16 safetensors read
  write_file_atomic(root / world::kTextEmbInfoFile, R"({"encoder": "x", "m": 2, "dim": 5, "width": 1})");
  EXPECT_NE(test::error_of([&] { TokenDataset ds(root); }).find("unknown key 'width'"), std::string::npos);
  for (auto* e : {"e0", "e1"})
    for (auto& f : fs::directory_iterator(root / "episodes" / e))
      if (f.path().stem() == "text_emb") fs::remove(f.path());
  EXPECT_NE(test::error_of([&] { TokenDataset ds(root); }).find("describes text embeddings, but no episode has"),
            std::string::npos);
}

// The model learns from the embeddings (its text projection trains, the unused word table does not), records
// who made them, and is scored on them; a dataset of another encoder is refused.
TEST(TextEmbeddings, WorldModelTrainsAndScoresOnEmbeddings) {
  test::TempDir dir;
  const fs::path root = make_embedded(dir);
  auto r = train_tiny(root, dir / "run");
  EXPECT_EQ(r.final_step, 4);
  world::WorldInfo info;
  auto model = world::load_world(dir / "run" / "world.safetensors", torch::kCPU, &info);
  EXPECT_EQ(info.text_encoder, "test-encoder");
  EXPECT_EQ(info.config.world.text_tokens, kM);
  EXPECT_EQ(info.config.world.text_dim, kDim);  // from the embeddings, not the config's 16
  EXPECT_EQ(info.vocab.size(), 2);              // no words
  torch::manual_seed(info.config.run.seed);
  world::WorldModel fresh(info.config.world, info.n(), info.K);
  EXPECT_FALSE(torch::allclose(model->text_proj->weight, fresh->text_proj->weight));
  EXPECT_TRUE(torch::equal(model->word_embedding->weight, fresh->word_embedding->weight));

  TokenDataset ds(root);
  auto text = world::text_source(info, ds);
  EXPECT_TRUE(text.embeddings);
  world::ScoreOptions so;
  so.mode = world::Conditioning::kText;
  auto s = world::score(model, ds, ds.windows({0, 1}, 4, 2), text, so);
  EXPECT_TRUE(std::isfinite(s.nats));
  EXPECT_GT(s.tokens, 0);

  world::write_text_emb_info(root, {"another-encoder", kM, kDim});
  EXPECT_NE(test::error_of([&] { world::text_source(info, TokenDataset(root)); })
                .find("text embeddings of another-encoder [m = 2, dim = 5], but the world model reads test-encoder"),
            std::string::npos);
}

// A fine-tune that gives a trained model another text (--text-encoder, --fresh-text): the text path starts afresh
// (word_embedding and text_proj as a fresh model has them, the projection at the new width, the words of this
// dataset), everything else comes from --init; keeping --init's kind of text from another encoder, or another m,
// is refused.
TEST(TextEmbeddings, FineTuneLearnsTheTextPathAfresh) {
  using Text = world::WorldTrainOptions::Text;
  test::TempDir dir;
  const fs::path root = make_embedded(dir);
  std::vector<double> kl;  // the distillation term of each step
  auto train = [&](const fs::path& out, Text text, const fs::path& init = {}, bool fresh = false,
                   const fs::path& teacher = {}) {
    world::WorldTrainOptions o;
    o.distill_from = teacher;
    o.tokens = root;
    o.out = out;
    o.steps = 2;
    o.val_every = 2;
    o.text = text;
    o.init = init;
    o.fresh_text = fresh;
    // Only the text path trains: what the fine-tune took from --init stays exactly --init's.
    if (!init.empty()) o.train_only = {"text_proj", "word_embedding"};
    kl.clear();
    return world::train_world(tiny_config(), o, [&](const world::WorldStepLog& l) { kl.push_back(l.distill); });
  };
  train(dir / "words", Text::Words);  // the dataset has embeddings; the built-in words are asked for
  world::WorldInfo wi;
  auto words = world::load_world(dir / "words" / "world.safetensors", torch::kCPU, &wi);
  ASSERT_FALSE(wi.embeds_text());
  ASSERT_GT(wi.vocab.size(), 2);

  auto r = train(dir / "to-emb", Text::Embeddings, dir / "words" / "world.safetensors");
  bool said = false;
  for (auto& n : r.notes) said |= n.find("starts afresh for embeddings of test-encoder") != std::string::npos;
  EXPECT_TRUE(said);
  world::WorldInfo ei;
  auto emb = world::load_world(dir / "to-emb" / "world.safetensors", torch::kCPU, &ei);
  EXPECT_EQ(ei.text_encoder, "test-encoder");
  EXPECT_EQ(emb->text_proj->weight.size(1), kDim);
  EXPECT_EQ(ei.vocab.size(), 2);
  EXPECT_TRUE(torch::equal(emb->head->weight, words->head->weight));
  EXPECT_TRUE(torch::equal(emb->spatial_pos, words->spatial_pos));
  torch::manual_seed(ei.config.run.seed);
  world::WorldModel fresh(ei.config.world, ei.n(), ei.K);
  EXPECT_TRUE(torch::equal(emb->word_embedding->weight, fresh->word_embedding->weight));  // unused by embeddings
  EXPECT_FALSE(torch::allclose(emb->text_proj->weight, fresh->text_proj->weight));         // trained from fresh

  // Taught by the words model (learning without forgetting across encoders): it reads its own words of the
  // same captions, and the term is there from the first step (the fresh text path predicts otherwise).
  r = train(dir / "taught", Text::Embeddings, dir / "words" / "world.safetensors", false, dir / "words" / "world.safetensors");
  said = false;
  for (auto& n : r.notes) said |= n.find("reads its own words of the captions") != std::string::npos;
  EXPECT_TRUE(said);
  ASSERT_EQ(kl.size(), 2u);
  for (double v : kl) EXPECT_TRUE(std::isfinite(v) && v >= 0) << v;
  EXPECT_GT(kl[0] + kl[1], 0.0);
  // A teacher that reads another encoder's embeddings cannot be given them.
  world::write_text_emb_info(root, {"another-encoder", kM, kDim});
  EXPECT_NE(test::error_of([&] { train(dir / "x0", Text::Embeddings, {}, false, dir / "to-emb" / "world.safetensors"); })
                .find("reads text embeddings of test-encoder, but this run's batches carry embeddings of another-encoder"),
            std::string::npos);
  world::write_text_emb_info(root, {"test-encoder", kM, kDim});

  // Back to words, afresh: the vocabulary is this dataset's, the word table starts as a fresh model's.
  r = train(dir / "back", Text::Words, dir / "to-emb" / "world.safetensors");
  world::WorldInfo bi;
  auto back = world::load_world(dir / "back" / "world.safetensors", torch::kCPU, &bi);
  EXPECT_FALSE(bi.embeds_text());
  EXPECT_TRUE(bi.vocab == wi.vocab);
  EXPECT_TRUE(torch::equal(back->head->weight, words->head->weight));
  // --fresh-text with the same kind of text: words relearned, not --init's.
  train(dir / "again", Text::Auto, dir / "words" / "world.safetensors", true);
  auto again = world::load_world(dir / "again" / "world.safetensors", torch::kCPU);
  EXPECT_FALSE(torch::allclose(again->word_embedding->weight, words->word_embedding->weight));

  // Keeping an embeddings model's text on another encoder's embeddings: refused, naming the way out.
  world::write_text_emb_info(root, {"another-encoder", kM, kDim});
  EXPECT_NE(test::error_of([&] { train(dir / "x1", Text::Auto, dir / "to-emb" / "world.safetensors"); })
                .find("has embeddings of another-encoder (--fresh-text learns its text path afresh for them)"),
            std::string::npos);
  r = train(dir / "other", Text::Auto, dir / "to-emb" / "world.safetensors", true);
  EXPECT_EQ(r.final_step, 2);
  // Another m: the model's positions are per token, so m must be --init's.
  world::write_text_embeddings(root / "episodes" / "e0", episode_emb(0, 8, kM + 1));
  world::write_text_embeddings(root / "episodes" / "e1", episode_emb(1, 10, kM + 1));
  world::write_text_emb_info(root, {"test-encoder", kM + 1, kDim});
  EXPECT_NE(test::error_of([&] { train(dir / "x2", Text::Embeddings, dir / "words" / "world.safetensors"); })
                .find("reads m = 2 text tokens per step, but " + root.string() + "'s embeddings have m = 3"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "x2" / "world.safetensors"));
}

TEST(TextEmbeddings, EmbedCaptionsIsCachedResumableAndKeyedByEncoder) {
  test::TempDir dir;
  const fs::path root = dir / "tokens";
  write_header(root);
  write_episode(root, EpisodeSpec{"e0", 8, "clear", 0});
  write_episode(root, EpisodeSpec{"e1", 10, "rain", 7});
  FakeEncoder enc("fake:1");
  auto r = world::embed_captions(root, enc, kM);
  EXPECT_EQ(r.episodes, 2);
  EXPECT_EQ(r.embedded, 2);
  EXPECT_EQ(r.captions, 18);  // every step's caption differs
  EXPECT_FALSE(fs::exists(root / world::kTextEmbPartialFile));
  TokenDataset ds(root);
  ASSERT_TRUE(ds.has_text_emb());
  EXPECT_EQ(ds.text_emb().encoder, "fake:1");
  auto ep = ds.episode(1);
  auto want = enc.encode(caption_at("rain", 4), kM);
  EXPECT_TRUE(torch::equal(torch::from_blob(const_cast<float*>(ep->text_emb.step(4)), {kM, kDim}), want));

  // Already there: nothing encoded.
  enc.calls = 0;
  EXPECT_EQ(world::embed_captions(root, enc, kM).embedded, 0);
  EXPECT_EQ(enc.calls, 0);
  // Interrupted after e0: a second run of the same encoder writes only e1.
  write_file_atomic(root / world::kTextEmbPartialFile, R"({"encoder": "fake:1", "m": 2})");
  fs::remove(root / "episodes" / "e1" / "text_emb.npy");
  EXPECT_FALSE(TokenDataset(root).has_text_emb());
  EXPECT_EQ(world::embed_captions(root, enc, kM).embedded, 1);
  EXPECT_TRUE(TokenDataset(root).has_text_emb());
  // Another encoder (or m) replaces them all.
  FakeEncoder other("fake:2", 3);
  EXPECT_EQ(world::embed_captions(root, other, kM).embedded, 2);
  EXPECT_EQ(TokenDataset(root).text_emb().dim, 3);
  EXPECT_EQ(world::embed_captions(root, other, 3).embedded, 2);
  // Word ids are not embeddings; a folder that is not a token dataset is named.
  text::WordEncoder words(text::Vocab{});
  EXPECT_NE(test::error_of([&] { world::embed_captions(root, words, kM); }).find("word ids, not embeddings"), std::string::npos);
  EXPECT_NE(test::error_of([&] { world::embed_captions(dir / "nothing", enc, kM); }).find("not a token dataset"),
            std::string::npos);
}

TEST(TextEmbeddings, PromptsGoThroughTheModelsOwnEncoder) {
  world::WorldInfo info;
  info.config = tiny_config();
  info.vocab = text::Vocab::build({"rain at night"}, 16);
  auto words = world::prompt_encoder(info, "w.safetensors", {});
  EXPECT_FALSE(words->embeds());
  EXPECT_EQ(words->encode("rain at night", kM).sizes(), (std::vector<int64_t>{kM}));
  EXPECT_NE(test::error_of([&] { world::prompt_encoder(info, "w.safetensors", "t5dir"); }).find("leave out --t5"),
            std::string::npos);
  info.text_encoder = "precomputed";
  EXPECT_NE(test::error_of([&] { world::prompt_encoder(info, "w.safetensors", {}); }).find("--text-emb FILE"),
            std::string::npos);
  info.text_encoder = "t5:base:0123456789ab";
  EXPECT_NE(test::error_of([&] { world::prompt_encoder(info, "w.safetensors", {}); }).find("give that encoder with --t5 DIR"),
            std::string::npos);
  EXPECT_TRUE(world::same_text_encoder("t5:base:0123456789ab", "t5:elsewhere:0123456789ab"));
  EXPECT_FALSE(world::same_text_encoder("t5:base:0123456789ab", "t5:base:0123456789ac"));
  EXPECT_FALSE(world::same_text_encoder("precomputed", "t5:precomputed"));

  // --text-emb: [m, dim] for every step or [steps, m, dim]; anything else names the file.
  test::TempDir dir;
  info.config.world.text_dim = int(kDim);
  save_tensors({{"text_emb", episode_emb(0, 1)[0]}}, dir / "p.safetensors");
  auto rows = world::read_prompt_embeddings(dir / "p.safetensors", info, 6);
  EXPECT_EQ(rows.sizes(), (std::vector<int64_t>{6, kM, kDim}));
  EXPECT_TRUE(torch::equal(rows[5], episode_emb(0, 1)[0]));
  world::write_text_embeddings(dir.path, episode_emb(0, 4));
  EXPECT_NE(test::error_of([&] { world::read_prompt_embeddings(dir / "text_emb.npy", info, 6); })
                .find("text_emb.npy: shape [4, 2, 5], want [m = 2, dim = 5] or [steps = 6, m, dim]"),
            std::string::npos);
}

// A sim session of a model that reads embeddings: its text goes through the encoder it is given, and without
// one a text prompt is refused with the flag to give.
TEST(TextEmbeddings, SimSessionTextThroughTheEncoder) {
  world::WorldInfo info;
  info.config = tiny_config();
  info.config.world.text_tokens = int(kM);
  info.config.world.text_dim = int(kDim);
  info.grid_h = kH;
  info.grid_w = kW;
  info.K = kK;
  info.text_encoder = "fake:1";
  torch::manual_seed(0);
  world::WorldModel model(info.config.world, info.n(), info.K);
  model->eval();
  {
    torch::NoGradGuard ng;  // weights far from their small initial scale, so that the text decides the draws
    for (auto& p : model->parameters())
      if (p.dim() == 2) p.mul_(25.0);
  }
  auto enc = std::make_shared<FakeEncoder>("fake:1");
  auto run = [&](const std::string& text) {
    sim::SimSession s(model, info, sim::SessionSettings{}, enc);
    s.start(torch::zeros({1, kN}, torch::kLong), {}, text);
    for (int k = 0; k < 2; ++k) s.step(sim::Action{}, std::nullopt);
    return s.tokens();
  };
  auto a = run("rain"), b = run("snow at night, turning left");
  EXPECT_TRUE(torch::equal(a, run("rain")));  // the same text and seed: the same frames
  EXPECT_FALSE(torch::equal(a, b));           // the text reaches the model
  EXPECT_GT(enc->calls, 0);
  sim::SimSession none(model, info, sim::SessionSettings{});
  none.start(torch::zeros({1, kN}, torch::kLong));
  EXPECT_NO_THROW(none.step(sim::Action{}));  // no text, no encoder needed
  EXPECT_NE(test::error_of([&] { none.step(sim::Action{}, std::string("rain")); }).find("gaia sim --t5 DIR"),
            std::string::npos);
}

// The whole path with a small T5 (tests/fixtures/t5, random weights in the Hugging Face layout): gaia text embed,
// world train --t5, world eval, generate and sim with text through the same T5; and the errors of a user who
// forgets --t5 or gives another checkpoint. generate with the same text twice gives the same tokens, and --text
// through the T5 equals --text-emb of that T5's embedding of it.
TEST(TextEmbCli, T5EmbeddingsTrainEvaluateAndPrompt) {
  test::TempDir dir;
  const fs::path root = dir / "tokens", t5 = test::source_dir() / "tests" / "fixtures" / "t5" / "relu";
  write_header(root);
  write_episode(root, EpisodeSpec{"e0", 12, "clear", 0});
  write_episode(root, EpisodeSpec{"e1", 12, "rain", 5});
  write_episode(root, EpisodeSpec{"e2", 12, "fog", 9});
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  auto r = test::run_gaia("text embed " + q(root) + " --t5 " + q(t5) + tiny);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("3 of 3 episodes embedded"), std::string::npos) << r.output;
  r = test::run_gaia("world train " + q(root) + " --text-encoder t5" + tiny + " --steps 3 --out " + q(dir / "run"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--text-encoder t5 needs --t5 DIR"), std::string::npos) << r.output;
  r = test::run_gaia("world train " + q(root) + " --text-encoder t5 --t5 " + q(t5) + tiny + " --steps 3 --val-every 3 --out " + q(dir / "run"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("already has embeddings"), std::string::npos) << r.output;  // embedded once
  EXPECT_NE(r.output.find("set world.text_tokens = 2 and world.text_dim = 32"), std::string::npos) << r.output;
  const fs::path w = dir / "run" / "world.safetensors";
  world::WorldInfo info;
  world::load_world(w, torch::kCPU, &info);
  EXPECT_EQ(info.text_encoder.rfind("t5:relu:", 0), 0u) << info.text_encoder;
  r = test::run_gaia("world eval " + q(root) + " --world " + q(w) + tiny + " --max-windows 4 --top-k-sweep 1,0 --out " + q(dir / "eval"));
  ASSERT_EQ(r.status, 0) << r.output;

  const std::string gen = "generate " + q(root) + " --world " + q(w) + tiny + " --episode e0 --prompt-frames 2 --frames 2 --seed 3";
  auto tokens_of = [&](const std::string& args, const std::string& out) {
    auto g = test::run_gaia(gen + args + " --out " + q(dir / out));
    EXPECT_EQ(g.status, 0) << g.output;
    SafetensorsFile f(dir / out / "rollout.safetensors");
    return tensor_from_view(f.get("tokens"));
  };
  auto a = tokens_of(" --t5 " + q(t5) + " --text 'rain at night' --guidance 4", "g1");
  EXPECT_TRUE(torch::equal(a, tokens_of(" --t5 " + q(t5) + " --text 'rain at night' --guidance 4", "g2")));
  torch::set_num_threads(1);  // as the binary runs it (--threads 1): the same sums to the last bit
  text::T5Encoder enc(t5);
  save_tensors({{"text_emb", enc.encode({"rain at night"}, 2)[0]}}, dir / "prompt.safetensors");
  EXPECT_TRUE(torch::equal(a, tokens_of(" --text-emb " + q(dir / "prompt.safetensors") + " --guidance 4", "g3")));

  r = test::run_gaia(gen + " --text 'rain at night' --out " + q(dir / "bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("give that encoder with --t5 DIR"), std::string::npos) << r.output;
  r = test::run_gaia(gen + " --t5 " + q(t5.parent_path() / "gated") + " --text 'rain' --out " + q(dir / "bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("was trained on embeddings of t5:relu:"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "bad" / "rollout.safetensors"));

  const fs::path requests = dir / "requests.jsonl";
  write_file_atomic(requests, "{\"op\": \"create\", \"prompt\": {\"episode\": 0, \"frames\": 2}, \"text\": \"rain\"}\n"
                              "{\"op\": \"step\", \"session\": 1, \"text\": \"fog at dusk\"}\n");
  for (const std::string& t5_flag : {" --t5 " + q(t5), std::string()}) {
    r = test::run_shell(test::gaia_command("sim " + q(root) + " --world " + q(w) + t5_flag + tiny + " --stdio") + " < " +
                        q(requests) + " 2>&1");
    ASSERT_EQ(r.status, 0) << r.output;
    std::istringstream lines(r.output);
    std::vector<int> statuses;
    for (std::string line; std::getline(lines, line);) statuses.push_back(nlohmann::json::parse(line)["status"]);
    // Without the T5, text is refused with a 400 (and the session is not made).
    EXPECT_EQ(statuses, (t5_flag.empty() ? std::vector<int>{400, 404} : std::vector<int>{200, 200})) << r.output;
  }
}
