// The world model end to end through the CLI on tiny data: synth -> tokenizer -> tokenize -> world train (resume)
// -> world eval -> generate (steering, text, guidance, futures), and the bad inputs named in the issue.
#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <sstream>

#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "gaia/data/frame_set.h"
#include "gaia/data/video_io.h"
#include "gaia/probe/trainer.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/io.h"
#include "test_util.h"

using namespace gaia;
using test::q;

namespace {

// The inputs the tests below share, built once for the whole suite (test::shared_fixture): a tiny procedural
// dataset, a tokenizer trained on it, its token dataset and a world model trained 10 steps on those tokens. Each
// test writes its own outputs under `dir`.
struct Pipeline {
  test::TempDir dir;
  fs::path ds, tok, tokens, run, trained;
  Pipeline() {
    const fs::path shared = test::shared_fixture("world-cli", [&](const fs::path& d) {
      auto r = test::run_gaia("synth --episodes 6 --seconds 4 --size 32x64 --seed 3 --out " + q(d / "ds"));
      if (r.status != 0) throw std::runtime_error(r.output);
      r = test::run_gaia("tokenizer train " + q(d / "ds") + tiny() + " --steps 20 --out " + q(d / "tok"));
      if (r.status != 0) throw std::runtime_error(r.output);
      r = test::run_gaia("tokenize " + q(d / "ds") + " --tokenizer " + q(d / "tok" / "tokenizer.safetensors") + tiny() +
                         " --out " + q(d / "tokens"));
      if (r.status != 0) throw std::runtime_error(r.output);
    });
    ds = shared / "ds";
    tok = shared / "tok";
    tokens = shared / "tokens";
    run = dir / "world";
    trained = test::shared_fixture("world-cli-trained", [&](const fs::path& d) {
                auto r = test::run_gaia("world train " + q(tokens) + tiny() + " --steps 10 --val-every 10 --out " + q(d));
                if (r.status != 0) throw std::runtime_error(r.output);
              }) /
              "world.safetensors";
  }
  static Pipeline& get() {
    static Pipeline p;
    return p;
  }
  static std::string tiny() { return " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1"; }
};

// A copy of the token dataset `from` at `to` (replaced), each episode's metadata passed through `edit`.
void copy_tokens_with(const fs::path& from, const fs::path& to, const std::function<void(nlohmann::json&)>& edit) {
  fs::remove_all(to);
  fs::copy(from, to, fs::copy_options::recursive);
  for (auto& e : fs::directory_iterator(to / "episodes")) {
    auto j = nlohmann::json::parse(read_file(e.path() / "episode.json"));
    edit(j);
    write_file_atomic(e.path() / "episode.json", j.dump(2));
  }
}

}  // namespace

TEST(WorldCli, TrainResumesEvaluatesAndGenerates) {
  auto& p = Pipeline::get();
  // Interrupted after 15 steps, then resumed to 30.
  auto r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --steps 30 --val-every 15 --stop-after 15 --out " + q(p.run));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_FALSE(fs::exists(p.run / "world.safetensors"));
  ASSERT_TRUE(fs::exists(p.run / "latest.safetensors"));  // the weights so far, usable while training goes on
  r = test::run_gaia("world eval " + q(p.tokens) + " --world " + q(p.run / "latest.safetensors") + p.tiny() +
                     " --max-windows 2 --out " + q(p.dir / "eval-latest"));
  EXPECT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --steps 30 --val-every 15 --out " + q(p.run));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("resumed"), std::string::npos) << r.output;
  ASSERT_TRUE(fs::exists(p.run / "world.safetensors"));

  r = test::run_gaia("world eval " + q(p.tokens) + " --world " + q(p.run / "world.safetensors") + p.tiny() + " --out " + q(p.dir / "eval"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto j = nlohmann::json::parse(read_file(p.dir / "eval" / "eval.json"));
  const double bits = j["bits_per_token"]["world_model"].get<double>();
  EXPECT_GT(bits, 0);
  EXPECT_LT(bits, 8.0 + 0.5);  // K = 256: a trained model is not worse than uniform
  EXPECT_GT(j["bits_per_token"]["xz"].get<double>(), 0);
  EXPECT_GT(j["bits_per_token"]["zstd"].get<double>(), 0);
  EXPECT_EQ(j["perplexity_by_position"].size(), 32u);
  EXPECT_TRUE(fs::exists(p.dir / "eval" / "perplexity_by_position.svg"));
  // Fig. 5 by default: argmax, the config's top-k and the whole distribution, each drawing the last frame of
  // held-out windows, against the real last frames. Argmax takes the most likely token at every position, so the
  // model finds its draws far likelier than real tokens or full samples, and it copies the frame before most.
  const auto& lf = j["last_frame"];
  ASSERT_EQ(lf["strategies"].size(), 3u) << lf.dump();
  EXPECT_EQ(lf["strategies"][0]["strategy"], "argmax");
  EXPECT_EQ(lf["strategies"][1]["top_k"], gaia::Config().world.top_k);
  EXPECT_EQ(lf["strategies"][2]["top_k"], 0);
  const double argmax_nats = lf["strategies"][0]["mean_nats"], sample_nats = lf["strategies"][2]["mean_nats"];
  EXPECT_LT(argmax_nats, lf["real"]["mean_nats"].get<double>() - 0.5) << lf.dump();
  EXPECT_LT(argmax_nats, sample_nats - 0.5) << lf.dump();
  EXPECT_EQ(lf["real"]["perplexity_by_position"].size(), 32u);
  EXPECT_GE(lf["strategies"][0]["copy_rate"].get<double>(), lf["strategies"][2]["copy_rate"].get<double>());
  EXPECT_TRUE(fs::exists(p.dir / "eval" / "perplexity_by_strategy.svg"));
  // Steering sensitivity: every scored frame after the first of a window falls in one turn bucket (no NaN actions
  // here); an untrained model's rises are small either way.
  const auto& ss = j["steering_sensitivity"];
  int64_t bucketed = 0;
  for (const char* k : {"left", "right", "straight"}) {
    bucketed += ss[k]["frames"].get<int64_t>();
    EXPECT_LT(std::abs(ss[k]["curvature_mirrored_rise_nats"].get<double>()), 1.0) << ss.dump();
  }
  EXPECT_EQ(bucketed, j["windows"].get<int64_t>() * (4 - 1)) << ss.dump();  // configs/tiny.yaml: context_steps 4
  r = test::run_gaia("world eval " + q(p.tokens) + " --world " + q(p.run / "world.safetensors") + p.tiny() +
                     " --max-windows 2 --top-k-sweep 4,0 --sweep-windows 1 --out " + q(p.dir / "eval-sweep"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto js = nlohmann::json::parse(read_file(p.dir / "eval-sweep" / "eval.json"));
  EXPECT_EQ(js["last_frame"]["windows"], 1);
  ASSERT_EQ(js["last_frame"]["strategies"].size(), 2u);
  EXPECT_EQ(js["last_frame"]["strategies"][0]["strategy"], "top-k, k = 4");
  r = test::run_gaia("world eval " + q(p.tokens) + " --world " + q(p.run / "world.safetensors") + p.tiny() +
                     " --top-k-sweep 1,300 --out " + q(p.dir / "eval-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--top-k-sweep: k must be in [0, 256]"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "eval-bad" / "eval.json"));

  // Two futures steered left from an episode prompt, with text and guidance, decoded into a preview.
  r = test::run_gaia("generate --world " + q(p.run / "world.safetensors") + " --tokenizer " + q(p.tok / "tokenizer.safetensors") +
                     " " + q(p.tokens) + " --episode 0 --prompt-frames 2 --frames 5 --futures 2 --steer left" +
                     " --text 'night, heavy rain' --guidance 2 --guidance-frames cosine --guidance-tokens linear" +
                     p.tiny() + " --seed 1 --out " + q(p.dir / "gen"));
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile f(p.dir / "gen" / "rollout.safetensors");
  auto t = tensor_from_view(f.get("tokens"));
  EXPECT_EQ(t.sizes(), (std::vector<int64_t>{2, 7, 4, 8}));
  EXPECT_TRUE(fs::exists(p.dir / "gen" / "preview.mp4"));
  auto acts = tensor_from_view(f.get("actions"));
  EXPECT_GT(acts[6][1].item<float>(), 0);  // steering left = positive curvature

  // Unconditional, from scratch, longer than the context (sliding window).
  r = test::run_gaia("generate --world " + q(p.run / "world.safetensors") + " --frames 7 --sampling sample" + p.tiny() +
                     " --out " + q(p.dir / "gen2"));
  ASSERT_EQ(r.status, 0) << r.output;
}

TEST(WorldCli, BadInputsAreClearErrors) {
  auto& p = Pipeline::get();
  const std::string w = " --world " + q(p.trained) + p.tiny();
  write_file_atomic(p.dir / "two.csv", "speed,curvature\n5,0\n5,0.01\n");
  auto r = test::run_gaia("generate" + w + " --frames 3 --actions " + q(p.dir / "two.csv") + " --out " + q(p.dir / "x"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("two.csv: 2 action rows but --frames is 3"), std::string::npos) << r.output;
  r = test::run_gaia("generate" + w + " " + q(p.tokens) + " --prompt-frames 9 --frames 1 --out " + q(p.dir / "x"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("context holds 4 steps"), std::string::npos) << r.output;
  // A token file with ids >= K.
  NpyArray a;
  a.dtype = DType::I16;
  a.shape = {10, 4, 8};
  std::vector<int16_t> v(320, 3);
  v[17] = 300;
  a.bytes.resize(v.size() * 2);
  std::memcpy(a.bytes.data(), v.data(), a.bytes.size());
  npy_write(p.dir / "bad.npy", a);
  r = test::run_gaia("world eval " + q(p.dir / "bad.npy") + w);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("bad.npy"), std::string::npos) << r.output;
  r = test::run_gaia("generate" + w + " --steer sideways --out " + q(p.dir / "x"));
  EXPECT_NE(r.output.find("sideways"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "x" / "rollout.safetensors"));
  // The weights fix the model: --set of its architecture is an error, not silently ignored.
  r = test::run_gaia("world eval " + q(p.tokens) + w + " --set world.n_layers=3 --out " + q(p.dir / "x"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("world.n_layers comes from the weights file"), std::string::npos) << r.output;
  r = test::run_gaia("generate" + w + " --frames 2 --set world.dropout=0.5 --out " + q(p.dir / "x"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("here only world.top_k, world.temperature, world.guide_actions_within_top_k, world.guidance_scale can be set"),
            std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "x" / "rollout.safetensors"));
  // The temperature stored with the model is generate's default: a file converted to 0.5 samples what --temperature
  // 0.5 and --set world.temperature=0.5 sample from the original.
  r = test::run_gaia("convert " + q(p.trained) + " --set world.temperature=0.5 --out " + q(p.dir / "warm.safetensors"));
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string roll = " " + q(p.tokens) + " --episode 0 --prompt-frames 2 --frames 2 --futures 2 --seed 4";
  std::vector<torch::Tensor> warm;
  const std::string orig = " --world " + q(p.trained);
  for (const std::string& how : {" --world " + q(p.dir / "warm.safetensors"), orig + " --temperature 0.5",
                                 orig + " --set world.temperature=0.5"}) {
    r = test::run_gaia("generate" + how + p.tiny() + roll + " --out " + q(p.dir / "warm"));
    ASSERT_EQ(r.status, 0) << r.output;
    warm.push_back(tensor_from_view(SafetensorsFile(p.dir / "warm" / "rollout.safetensors").get("tokens")));
  }
  EXPECT_TRUE(torch::equal(warm[0], warm[1]));
  EXPECT_TRUE(torch::equal(warm[0], warm[2]));
  // ... but its sampling key reaches the sampler: with k = 1 two futures of one prompt are the same.
  r = test::run_gaia("generate" + w + " " + q(p.tokens) + " --episode 0 --prompt-frames 2 --frames 2 --futures 2" +
                     " --set world.top_k=1 --seed 3 --out " + q(p.dir / "k1"));
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile f(p.dir / "k1" / "rollout.safetensors");
  auto t = tensor_from_view(f.get("tokens"));
  EXPECT_TRUE(torch::equal(t[0], t[1]));
  // Steering guidance contrasts the command with its mirror image by default, with null actions on request (which
  // frames that gives is WorldRollout.NegativeActionsReplaceTheNullOnes; this barely trained model may not show it).
  const std::string steer = "generate" + w + " " + q(p.tokens) + " --episode 0 --prompt-frames 2 --frames 2" +
                            " --steer strong-left --guidance 30 --sampling argmax --out ";
  r = test::run_gaia(steer + q(p.dir / "mirror"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(steer + q(p.dir / "null") + " --action-negative null");
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile fm(p.dir / "mirror" / "rollout.safetensors"), fn(p.dir / "null" / "rollout.safetensors");
  EXPECT_EQ(nlohmann::json::parse(fm.metadata().at("gaia.rollout"))["action_negative"], "mirror");
  EXPECT_EQ(nlohmann::json::parse(fn.metadata().at("gaia.rollout"))["action_negative"], "null");
  r = test::run_gaia(steer + q(p.dir / "bad-negative") + " --action-negative sideways");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--action-negative"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "bad-negative" / "rollout.safetensors"));
}

// Fine-tuning (--init): the run starts from the given weights and keeps their text vocabulary, even on data whose
// captions would give another one (here a bare token file without captions); an architecture mismatch is an error.
TEST(WorldCli, FineTuneStartsFromInitWeightsAndKeepsTheirVocabulary) {
  auto& p = Pipeline::get();
  fs::path first;
  for (auto& e : fs::directory_iterator(p.tokens / "episodes")) first = std::max(first, e.path());
  fs::copy_file(first / "tokens.npy", p.dir / "bare.npy", fs::copy_options::overwrite_existing);
  const fs::path init = p.trained, ft = p.dir / "finetune";
  // lr 0: AdamW leaves every weight exactly where --init put it.
  auto r = test::run_gaia("world train " + q(p.dir / "bare.npy") + p.tiny() + " --init " + q(init) +
                          " --set world.lr=0 --steps 2 --val-every 100 --out " + q(ft));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("initialised from"), std::string::npos) << r.output;
  world::WorldInfo a, b;
  auto m0 = world::load_world(init, torch::kCPU, &a);
  auto m1 = world::load_world(ft / "world.safetensors", torch::kCPU, &b);
  EXPECT_GT(a.vocab.size(), 4);
  EXPECT_TRUE(a.vocab == b.vocab);
  auto p1 = m1->named_parameters();
  size_t n = 0;
  for (auto& kv : m0->named_parameters()) {
    ASSERT_NE(p1.find(kv.key()), nullptr) << kv.key();
    EXPECT_TRUE(torch::equal(kv.value(), p1[kv.key()])) << kv.key();
    ++n;
  }
  EXPECT_GT(n, 10u);
  // Without --init the same data gives no vocabulary at all: the test above is not vacuous.
  r = test::run_gaia("world train " + q(p.dir / "bare.npy") + p.tiny() + " --steps 1 --val-every 100 --out " +
                     q(p.dir / "scratch"));
  ASSERT_EQ(r.status, 0) << r.output;
  world::WorldInfo c;
  world::load_world(p.dir / "scratch" / "world.safetensors", torch::kCPU, &c);
  EXPECT_FALSE(c.vocab == a.vocab);

  r = test::run_gaia("world train " + q(p.dir / "bare.npy") + p.tiny() + " --init " + q(init) +
                     " --set world.d_model=32 --steps 2 --out " + q(p.dir / "mismatch"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("world.safetensors: '"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("has shape"), std::string::npos) << r.output;
  r = test::run_gaia("world train " + q(p.dir / "bare.npy") + p.tiny() + " --init " + q(p.dir / "missing.safetensors") +
                     " --steps 2 --out " + q(p.dir / "missing"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("missing.safetensors"), std::string::npos) << r.output;
}

// --train-only with a new action MLP (world.action_mlp): only the named parameters move, the MLP the --init model
// lacks starts from zero output and trains, everything else stays bit for bit; a prefix that names nothing is one
// error line.
TEST(WorldCli, FineTuneTrainsOnlyTheNamedParameters) {
  auto& p = Pipeline::get();
  const fs::path init = p.trained, ft = p.dir / "action-mlp";
  auto r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --init " + q(init) +
                          " --set world.action_mlp=16 --set world.lr=1e-2 --set world.warmup_steps=0"
                          " --train-only curvature_proj,curvature_mlp --steps 3 --val-every 100 --out " + q(ft));
  ASSERT_EQ(r.status, 0) << r.output;
  world::WorldInfo info;
  auto m0 = world::load_world(init, torch::kCPU), m1 = world::load_world(ft / "world.safetensors", torch::kCPU, &info);
  EXPECT_EQ(info.config.world.action_mlp, 16);
  auto p0 = m0->named_parameters();
  size_t same = 0, moved = 0;
  for (auto& kv : m1->named_parameters()) {
    const std::string& k = kv.key();
    if (k.rfind("curvature_", 0) == 0) {
      if (k == "curvature_mlp.2.weight" || k == "curvature_proj.weight") {
        const auto* before = p0.find(k);
        auto was = before ? *before : torch::zeros_like(kv.value());  // the new MLP's output layer starts at 0
        EXPECT_FALSE(torch::equal(kv.value(), was)) << k;
        ++moved;
      }
      continue;
    }
    if (k.rfind("speed_mlp.2.", 0) == 0) {  // not named: the new speed MLP keeps its zero output
      EXPECT_EQ(kv.value().abs().max().item<double>(), 0.0) << k;
      continue;
    }
    if (k.rfind("speed_mlp.", 0) == 0) continue;  // its (random) hidden layer
    ASSERT_NE(p0.find(k), nullptr) << k;
    EXPECT_TRUE(torch::equal(kv.value(), p0[k])) << k;
    ++same;
  }
  EXPECT_EQ(moved, 2u);
  EXPECT_GT(same, 10u);

  r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --init " + q(init) +
                     " --train-only curvature_proj,nosuch_layer --steps 1 --out " + q(p.dir / "bad-only"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--train-only: no world model parameter starts with 'nosuch_layer'"), std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "bad-only" / "world.safetensors"));
}

// --distill-from (learning without forgetting, world/distill.h): metrics.jsonl records the KL term to the teacher on
// the examples that are not action-conditioned, and with --distill-other-text the one under other examples'
// captions. Each is 0 at the first step (the model starts as the teacher), and a heavy weight keeps it below what a
// negligible one lets it grow to. A teacher with another text vocabulary, a missing teacher, a weight of 0, and
// --distill-other-text without a teacher or without captions are one error line each, with nothing written.
TEST(WorldCli, FineTuneDistilsFromTheTeacher) {
  auto& p = Pipeline::get();
  const fs::path init = p.trained;
  const std::string base = "world train " + q(p.tokens) + p.tiny() + " --init " + q(init) + " --distill-from " +
                           q(init) + " --set world.lr=1e-2 --set world.warmup_steps=0 --set world.p_action=0.2" +
                           " --set world.p_text=0.6 --steps 5 --val-every 100 --distill-other-text";
  auto r = test::run_gaia(base + " --distill-weight 100 --out " + q(p.dir / "distil-heavy"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("distilling text-only and unconditional predictions from"), std::string::npos) << r.output;
  r = test::run_gaia(base + " --distill-weight 1e-9 --out " + q(p.dir / "distil-light"));
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* key : {"distill", "distill_other"}) {
    auto heavy = test::jsonl_numbers(p.dir / "distil-heavy" / "metrics.jsonl", key);
    auto light = test::jsonl_numbers(p.dir / "distil-light" / "metrics.jsonl", key);
    ASSERT_EQ(heavy.size(), 5u) << key;
    ASSERT_EQ(light.size(), 5u) << key;
    EXPECT_NEAR(heavy[0], 0.0, 1e-5) << key;
    EXPECT_NEAR(light[0], 0.0, 1e-5) << key;
    double h = 0, l = 0;
    for (size_t i = 2; i < 5; ++i) {
      EXPECT_GE(heavy[i], 0.0) << key;
      h += heavy[i];
      l += light[i];
    }
    EXPECT_GT(l, 1e-4) << key;  // the model has moved away from the teacher ...
    EXPECT_LT(h, 0.5 * l) << key << ": heavy " << h << " light " << l;  // ... less where the term weighs
  }

  // A teacher whose text ids mean other words: a model trained from scratch on a bare token file has no vocabulary.
  fs::path first;
  for (auto& e : fs::directory_iterator(p.tokens / "episodes")) first = std::max(first, e.path());
  fs::copy_file(first / "tokens.npy", p.dir / "bare-distil.npy", fs::copy_options::overwrite_existing);
  r = test::run_gaia("world train " + q(p.dir / "bare-distil.npy") + p.tiny() + " --steps 1 --val-every 100 --out " +
                     q(p.dir / "novocab"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --init " + q(init) + " --distill-from " +
                     q(p.dir / "novocab" / "world.safetensors") + " --steps 1 --out " + q(p.dir / "distil-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("its text vocabulary differs"), std::string::npos) << r.output;
  // Other examples' captions need captions: the bare token file has none.
  r = test::run_gaia("world train " + q(p.dir / "bare-distil.npy") + p.tiny() + " --distill-from " +
                     q(p.dir / "novocab" / "world.safetensors") + " --distill-other-text --steps 1 --out " +
                     q(p.dir / "distil-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--distill-other-text: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("has no captions"), std::string::npos) << r.output;
  r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --distill-from " + q(p.dir / "nosuch.safetensors") +
                     " --steps 1 --out " + q(p.dir / "distil-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("nosuch.safetensors"), std::string::npos) << r.output;
  r = test::run_gaia(base + " --distill-weight 0 --out " + q(p.dir / "distil-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--distill-weight must be a positive number"), std::string::npos) << r.output;
  r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --distill-other-text --steps 1 --out " +
                     q(p.dir / "distil-bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--distill-other-text needs --distill-from"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "distil-bad" / "world.safetensors"));
}

// --distill-procedural-only (a fine-tune that adds real drives to a teacher that knows only the procedural world):
// on procedural windows the term is the same as without the flag, step for step; on drives a camera recorded it is
// never applied.
TEST(WorldCli, DistilsOnlyProceduralWindowsWhenAsked) {
  auto& p = Pipeline::get();
  // The same tokens as recorded footage: only their episodes' source differs.
  const fs::path recorded = p.dir / "recorded-tokens";
  copy_tokens_with(p.tokens, recorded, [](nlohmann::json& j) { j["source"] = "dashcam.mp4"; });
  // ... and as procedural drives whose conditions change (synth --change-at): new to the teacher too.
  const fs::path changing = p.dir / "changing-tokens";
  copy_tokens_with(p.tokens, changing, [](nlohmann::json& j) {
    ASSERT_EQ(j["source"].get<std::string>().rfind("synth:", 0), 0u) << j["source"];
    j["extra"]["synth_change_at"] = "2";
  });
  const std::string base = p.tiny() + " --init " + q(p.trained) + " --distill-from " + q(p.trained) +
                           " --set world.lr=1e-2 --set world.warmup_steps=0 --set world.p_action=0.2 --set world.p_text=0.6 --steps 4"
                           " --val-every 100";
  auto kl = [&](const fs::path& tokens, const std::string& flags, const std::string& out) {
    auto r = test::run_gaia("world train " + q(tokens) + base + flags + " --out " + q(p.dir / out));
    EXPECT_EQ(r.status, 0) << r.output;
    return test::jsonl_numbers(p.dir / out / "metrics.jsonl", "distill");
  };
  const auto all = kl(p.tokens, "", "distil-all");
  const auto procedural = kl(p.tokens, " --distill-procedural-only", "distil-procedural");
  const auto real = kl(recorded, " --distill-procedural-only", "distil-real");
  const auto changed = kl(changing, " --distill-procedural-only", "distil-changing");
  const auto changed_all = kl(changing, "", "distil-changing-all");
  ASSERT_EQ(all.size(), 4u);
  ASSERT_EQ(procedural.size(), 4u);
  ASSERT_EQ(real.size(), 4u);
  ASSERT_EQ(changed.size(), 4u);
  ASSERT_EQ(changed_all.size(), 4u);
  EXPECT_GT(all[3], 1e-6);  // the term is there to keep ...
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(procedural[i], all[i]) << i;  // ... on procedural windows, exactly ...
    EXPECT_EQ(real[i], 0.0) << i;           // ... and never on recorded ones
    EXPECT_EQ(changed[i], 0.0) << i;        // ... nor on drives whose conditions change,
    EXPECT_EQ(changed_all[i], all[i]) << i;  // which without the flag are held like any other
  }
  auto r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --distill-procedural-only --steps 1 --out " +
                          q(p.dir / "distil-none"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--distill-procedural-only needs --distill-from"), std::string::npos) << r.output;
}

// gaia world calibrate: the fitted world.copy_bias is stored with the model, lowers the cross-entropy of the
// training windows it was fitted on, and a second calibration of the result finds the same value (the fit starts
// from the model's own bias). Bad flags are one error line with nothing written.
// Calibration in the recipe: each validation fits the copy bias on training windows, scores the held-out ones with
// it, and the weights written carry it, so `world eval` of them reads the trainer's own figure; --no-calibrate
// writes the paper's model (bias 0) and reports no bias.
TEST(WorldCli, ValidationCalibratesTheCopyBiasItWrites) {
  auto& p = Pipeline::get();
  auto last_val = [](const fs::path& run) {
    nlohmann::json v;
    std::istringstream in(read_file(run / "metrics.jsonl"));
    for (std::string line; std::getline(in, line);)
      if (auto j = nlohmann::json::parse(line); j.contains("val") && !j["val"].is_null() && !j["val"].empty()) v = j["val"];
    return v;
  };
  auto r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --steps 4 --val-every 4 --out " + q(p.dir / "cal-run"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("copy bias"), std::string::npos) << r.output;  // in the validation line
  const auto v = last_val(p.dir / "cal-run");
  ASSERT_TRUE(v.contains("copy_bias")) << v.dump();
  const double bias = v["copy_bias"].get<double>();
  EXPECT_NE(bias, 0.0);
  EXPECT_NE(v["bits_per_token"].get<double>(), v["bits_per_token_uncalibrated"].get<double>());
  for (const char* f : {"world.safetensors", "best.safetensors", "latest.safetensors"}) {
    world::WorldInfo info;
    world::load_world(p.dir / "cal-run" / f, torch::kCPU, &info);
    EXPECT_DOUBLE_EQ(info.config.world.copy_bias, bias) << f;
  }
  r = test::run_gaia("world eval " + q(p.tokens) + " --world " + q(p.dir / "cal-run" / "world.safetensors") + p.tiny() +
                     " --max-windows 64 --out " + q(p.dir / "cal-eval"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto e = nlohmann::json::parse(read_file(p.dir / "cal-eval" / "eval.json"));
  // The validation line scores each half of the held-out windows with the other half's fit; the eval scores them all
  // with the weights' bias, the two fits' mean: near it, and never above the uncalibrated score by much.
  EXPECT_NEAR(e["bits_per_token"]["world_model"].get<double>(), v["bits_per_token"].get<double>(), 0.05);
  EXPECT_LT(e["bits_per_token"]["world_model"].get<double>(), v["bits_per_token_uncalibrated"].get<double>() + 1e-3);
  EXPECT_EQ(e["precision"], "fp32");
  // --precision bf16 scores with bf16 products where the CPU has them (else fp32, said): near fp32's figure.
  r = test::run_gaia("world eval " + q(p.tokens) + " --world " + q(p.dir / "cal-run" / "world.safetensors") + p.tiny() +
                     " --max-windows 64 --precision bf16 --out " + q(p.dir / "cal-eval-bf16"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto b = nlohmann::json::parse(read_file(p.dir / "cal-eval-bf16" / "eval.json"));
  EXPECT_EQ(b["precision"], cpu_has_bf16() ? "bf16" : "fp32");
  EXPECT_NEAR(b["bits_per_token"]["world_model"].get<double>(), e["bits_per_token"]["world_model"].get<double>(), 0.05);
  if (cpu_has_bf16()) {
    EXPECT_NE(b["bits_per_token"]["world_model"].get<double>(), e["bits_per_token"]["world_model"].get<double>());
  }
  r = test::run_gaia("world train " + q(p.tokens) + p.tiny() + " --steps 4 --val-every 4 --no-calibrate --out " +
                     q(p.dir / "uncal-run"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto u = last_val(p.dir / "uncal-run");
  EXPECT_FALSE(u.contains("copy_bias")) << u.dump();
  EXPECT_DOUBLE_EQ(u["bits_per_token"].get<double>(), v["bits_per_token_uncalibrated"].get<double>());  // same run
  world::WorldInfo info;
  world::load_world(p.dir / "uncal-run" / "world.safetensors", torch::kCPU, &info);
  EXPECT_EQ(info.config.world.copy_bias, 0.0);
}

TEST(WorldCli, CalibrateFitsAndStoresTheCopyBias) {
  auto& p = Pipeline::get();
  auto parse = [](const std::string& out, const std::string& after) {
    auto at = out.find(after);
    EXPECT_NE(at, std::string::npos) << out;
    return at == std::string::npos ? NAN : std::stod(out.substr(at + after.size()));
  };
  auto r = test::run_gaia("world calibrate " + q(p.tokens) + " --world " + q(p.trained) + p.tiny() +
                          " --max-windows 16 --out " + q(p.dir / "cal.safetensors"));
  ASSERT_EQ(r.status, 0) << r.output;
  const double bias = parse(r.output, "world.copy_bias ");
  const auto ce = r.output.substr(r.output.find("cross-entropy "));  // "cross-entropy A -> B nats"
  const double before = parse(ce, "cross-entropy "), after = parse(ce, "-> ");
  EXPECT_LT(after, before) << r.output;  // the bias is fitted on these windows: it can only lower their loss
  world::WorldInfo info;
  world::load_world(p.dir / "cal.safetensors", torch::kCPU, &info);
  EXPECT_NEAR(info.config.world.copy_bias, bias, 1e-4);
  EXPECT_NE(bias, 0.0);
  r = test::run_gaia("world calibrate " + q(p.tokens) + " --world " + q(p.dir / "cal.safetensors") + p.tiny() +
                     " --max-windows 16 --out " + q(p.dir / "cal2.safetensors"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NEAR(parse(r.output, "world.copy_bias "), bias, 1e-3) << r.output;
  EXPECT_NEAR(parse(r.output, "(was "), bias, 1e-4) << r.output;

  // --without-meta leaves out the episodes with that key: every synth drive has a synth_index.
  r = test::run_gaia("world calibrate " + q(p.tokens) + " --world " + q(p.trained) + p.tiny() +
                     " --without-meta synth_index --out " + q(p.dir / "bad.safetensors"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("in the episodes without synth_index"), std::string::npos) << r.output;
  r = test::run_gaia("world calibrate " + q(p.tokens) + " --world " + q(p.trained) + p.tiny() +
                     " --max-windows 0 --out " + q(p.dir / "bad.safetensors"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--max-windows must be >= 1"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "bad.safetensors"));
}

// gaia eval end to end on the tiny pipeline (shipped probes: they are fully convolutional, any frame size works):
// every part runs, the numbers are where they must be, and the report is written.
TEST(EvalCli, MeasuresControlFuturesAndLongRolloutsAndWritesTheReport) {
  auto& p = Pipeline::get();
  const fs::path models = test::source_dir() / "models";
  const std::string base = "eval " + q(p.tokens) + " --world " + q(p.trained) + " --tokenizer " +
                           q(p.tok / "tokenizer.safetensors") + " --dynamics-probe " +
                           q(models / "probe-dynamics.safetensors") + " --scene-probe " +
                           q(models / "probe-scene.safetensors") + p.tiny();
  const int64_t K = probe::load_probe(models / "probe-dynamics.safetensors", torch::kCPU)->frames;
  auto r = test::run_gaia(base + " " + q(p.ds) + " --prompts 2 --prompt-frames 2 --frames " +
                          std::to_string(K - 1) + " --futures 2" +
                          " --text-frames 1 --scales 0,2 --long-seconds 2 --window-seconds 1 --long-rollouts 2 --action-guidance 1.5 --out " +
                          q(p.dir / "eval"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto j = nlohmann::json::parse(read_file(p.dir / "eval" / "eval.json"));
  const auto& a = j["action_control"];
  EXPECT_EQ(a["rollouts"].get<int>(), 2 * 8);  // prompts x commands
  EXPECT_EQ(a["guidance_scale"].get<double>(), 1.5);
  EXPECT_EQ(a["negative_actions"], "mirror");  // the default: the command turning the other way
  EXPECT_EQ(a["probe_frames"].get<int64_t>(), K);  // the read-back windows span the last prompt frame and all generated
  for (auto it = a["per_command"].begin(); it != a["per_command"].end(); ++it) {  // one window here, its mean = the whole
    const auto& w = it.value()["read_curvature_by_window"];
    ASSERT_EQ(w.size(), 1u) << it.key();
    EXPECT_NEAR(w[0].get<double>(), it.value()["read_curvature"].get<double>(), 1e-9) << it.key();
  }
  // Per command, each prompt's read-back (their mean is the command's) and the command's sign accuracy; the steered
  // commands have as many rollouts each, so the mean of their accuracies is the overall one.
  double sign_sum = 0;
  int steered = 0;
  for (auto it = a["per_command"].begin(); it != a["per_command"].end(); ++it) {
    const auto& c = it.value();
    const auto by = c["read_curvature_by_rollout"].get<std::vector<double>>();
    ASSERT_EQ(by.size(), 2u) << it.key();  // one per prompt
    EXPECT_NEAR((by[0] + by[1]) / 2, c["read_curvature"].get<double>(), 1e-9) << it.key();
    const double cmd = c["commanded_curvature"].get<double>();
    if (std::abs(cmd) < 0.002) {
      EXPECT_FALSE(c.contains("steering_sign_accuracy")) << it.key();  // straight, slow, fast
      continue;
    }
    const double right = ((by[0] > 0) == (cmd > 0)) + ((by[1] > 0) == (cmd > 0));
    EXPECT_DOUBLE_EQ(c["steering_sign_accuracy"].get<double>(), right / 2) << it.key();
    sign_sum += right / 2;
    ++steered;
  }
  EXPECT_EQ(steered, 5);  // left, right, strong-left, strong-right, drift-right
  EXPECT_NEAR(sign_sum / steered, a["conditioned"]["steering_sign_accuracy"].get<double>(), 1e-12);
  for (const char* k : {"conditioned", "without_actions", "counterfactual_probe", "counterfactual_probe_tokenized"})
    EXPECT_TRUE(a[k].contains("curvature_spearman")) << k;
  // Teacher-forced replay under the command and the counter-command: the straight command at the kept speed is its
  // own counter-command, so the replay scores the same under both; every turn's gain is a finite number.
  EXPECT_EQ(a["per_command"]["straight"]["replay_nats_gain_over_counter_command"].get<double>(), 0.0);
  EXPECT_EQ(a["per_command"]["straight"]["replay_prefers_command"].get<double>(), 0.0);
  for (const char* k : {"left", "right", "strong-left", "strong-right"}) {
    const auto& c = a["per_command"][k];
    EXPECT_TRUE(std::isfinite(c["replay_nats_gain_over_counter_command"].get<double>())) << k;
    EXPECT_NE(c["replay_nats_gain_over_counter_command"].get<double>(), 0.0) << k;
    EXPECT_TRUE(std::isfinite(c["read_curvature_counterfactual_tokenized"].get<double>())) << k;
    EXPECT_TRUE(std::isfinite(c["replay_nats_gain_over_no_action"].get<double>())) << k;
  }
  EXPECT_GT(a["per_command"]["left"]["read_curvature_counterfactual"].get<double>(),
            a["per_command"]["right"]["read_curvature_counterfactual"].get<double>());
  EXPECT_GT(a["counterfactual"]["psnr_db"].get<double>(), 5.0);
  EXPECT_GE(a["counterfactual"]["fd_probe"].get<double>(), 0.0);
  // Text: one row per scale, then the negative prompt and the schedules; accuracies are fractions.
  const auto& runs = j["text_control"]["runs"];
  ASSERT_EQ(runs.size(), 4u);
  for (const auto& row : runs) {
    for (const char* k : {"weather", "time_of_day", "light"}) {
      EXPECT_GE(row[k].get<double>(), 0.0);
      EXPECT_LE(row[k].get<double>(), 1.0);
    }
    // What each prompt's frames were read as: fractions over the attribute's classes that sum to one, the prompted
    // class's share being its accuracy.
    ASSERT_EQ(row["read_as"].size(), row["per_target"].size()) << row.dump();
    for (auto it = row["read_as"].begin(); it != row["read_as"].end(); ++it) {
      double sum = 0;
      for (auto c = it.value().begin(); c != it.value().end(); ++c) {
        EXPECT_GT(c.value().get<double>(), 0.0) << it.key() << " " << c.key();
        sum += c.value().get<double>();
      }
      EXPECT_NEAR(sum, 1.0, 1e-9) << it.key();
      EXPECT_NEAR(it.value().value(it.key(), 0.0), row["per_target"][it.key()].get<double>(), 1e-12) << it.key();
    }
  }
  // The ceiling row: the probe on real held-out frames through the same decoder, for the prompted kinds it has.
  const auto& real = j["text_control"]["real_decoded"];
  EXPECT_EQ(real["frames"].get<int>(), 16);
  EXPECT_GE(real["episodes"].get<int>(), 1) << real.dump();
  for (auto it = real["per_target"].begin(); it != real["per_target"].end(); ++it) {
    EXPECT_GE(it.value().get<double>(), 0.0) << it.key();
    EXPECT_LE(it.value().get<double>(), 1.0) << it.key();
  }
  const double dist = j["futures"]["mean_pairwise_token_distance"].get<double>();
  EXPECT_GT(dist, 0.0);  // top-k sampling: futures differ
  EXPECT_LE(dist, 1.0);
  const auto& lr = j["long_rollout"];
  EXPECT_EQ(lr["frames"].get<int>(), 13);  // 2 s at 6.25 Hz, rounded
  EXPECT_EQ(lr["windows"].size(), 2u);     // two 1 s windows of 6 frames
  // The real windows' own spread: ordered percentiles around the mean, a fraction of them within 10% of it.
  EXPECT_GE(lr["real_windows"].get<int>(), 1);
  for (const char* k : {"real_copy_rate_spread", "real_entropy_bits_spread"}) {
    const auto& s = lr[k];
    EXPECT_LE(s["p10"].get<double>(), s["p50"].get<double>()) << k;
    EXPECT_LE(s["p50"].get<double>(), s["p90"].get<double>()) << k;
    EXPECT_GE(s["within_10_percent_of_mean"].get<double>(), 0.0) << k;
    EXPECT_LE(s["within_10_percent_of_mean"].get<double>(), 1.0) << k;
  }
  // Two rollouts from two held-out prompts: each window's statistic is the mean of the two rollouts' windows, the
  // pooled one the mean over every window, and the within-10% verdicts follow from the numbers.
  EXPECT_EQ(lr["rollouts"].get<int>(), 2);
  EXPECT_GE(lr["prompt_episodes"].get<int>(), 1);  // the tiny set may have one held-out drive for both
  EXPECT_LE(lr["prompt_episodes"].get<int>(), 2);
  double pooled = 0, worst = 0;
  for (const auto& w : lr["windows"]) {
    EXPECT_GE(w["copy_rate"].get<double>(), 0.0);
    EXPECT_LE(w["entropy_bits"].get<double>(), 8.0 + 1e-9);  // K = 256
    const auto& per = w["copy_rate_per_rollout"];
    ASSERT_EQ(per.size(), 2u);
    EXPECT_NEAR(w["copy_rate"].get<double>(), (per[0].get<double>() + per[1].get<double>()) / 2, 1e-12);
    // The standard error of a mean of two: |a - b| / 2.
    EXPECT_NEAR(w["copy_rate_std_error"].get<double>(), std::abs(per[0].get<double>() - per[1].get<double>()) / 2, 1e-12);
    pooled += w["copy_rate"].get<double>() / double(lr["windows"].size());
    worst = std::max({worst, std::abs(w["copy_rate_vs_real"].get<double>()), std::abs(w["entropy_vs_real"].get<double>())});
  }
  EXPECT_NEAR(lr["pooled"]["copy_rate"].get<double>(), pooled, 1e-12);
  EXPECT_NEAR(lr["pooled"]["copy_rate_vs_real"].get<double>(), pooled / lr["real_copy_rate"].get<double>() - 1, 1e-9);
  EXPECT_NEAR(lr["max_relative_difference"].get<double>(), worst, 1e-12);
  EXPECT_EQ(lr["within_10_percent"].get<bool>(), worst <= 0.10);
  EXPECT_GT(lr["real_copy_rate_std_error"].get<double>() + lr["real_entropy_bits_std_error"].get<double>(), 0.0);
  for (const char* f : {"report.html", "report.json", "videos/action_generated.gif", "videos/action_counterfactual.gif",
                        "videos/text_prompts.gif", "videos/futures.gif", "videos/long_rollout.gif",
                        "plots/action_curvature.svg", "plots/text_guidance.svg", "plots/long_rollout.svg"})
    EXPECT_TRUE(fs::exists(p.dir / "eval" / f)) << f;
  EXPECT_FALSE(fs::exists(p.dir / "eval" / "counterfactual"));  // replay frames are temporary
  const std::string html = read_file(p.dir / "eval" / "report.html");
  for (const char* s : {"Action control", "Text control", "Multiple futures", "Long rollout", "data:image/gif;base64,"})
    EXPECT_NE(html.find(s), std::string::npos) << s;

  EXPECT_EQ(j["temperature"].get<double>(), 1.0);  // the world model's config
  EXPECT_TRUE(j["guide_actions_within_top_k"].get<bool>());

  // --set world.temperature reaches the sampler: the same long rollout, sharper distributions, other tokens.
  // With --world-eval the likelihood figures and both Fig. 5 plots join the report.
  r = test::run_gaia("world eval " + q(p.tokens) + " --world " + q(p.trained) + p.tiny() +
                     " --max-windows 2 --sweep-windows 1 --out " + q(p.dir / "world-eval"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(base + " --only long --long-seconds 2 --window-seconds 1 --set world.temperature=0.3 --set world.guide_actions_within_top_k=false"
                     " --world-eval " +
                     q(p.dir / "world-eval") + " --out " + q(p.dir / "eval-cold"));
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"plots/perplexity_by_position.svg", "plots/perplexity_by_strategy.svg"})
    EXPECT_TRUE(fs::exists(p.dir / "eval-cold" / f)) << f;
  EXPECT_NE(read_file(p.dir / "eval-cold" / "report.html").find("the last frame drawn by argmax"), std::string::npos);
  auto cold = nlohmann::json::parse(read_file(p.dir / "eval-cold" / "eval.json"));
  EXPECT_EQ(cold["world_model"]["last_frame"]["strategies"].size(), 3u);
  EXPECT_EQ(cold["temperature"].get<double>(), 0.3);
  EXPECT_FALSE(cold["guide_actions_within_top_k"].get<bool>());
  EXPECT_NE(cold["long_rollout"]["windows"][1]["entropy_bits"].get<double>(), lr["windows"][1]["entropy_bits"].get<double>());

  // --precision bf16: the rollouts' products in bf16 where the CPU has them (else fp32, said); the real windows the
  // rollouts are set against are the data's and do not change.
  EXPECT_EQ(j["precision"], "fp32");
  r = test::run_gaia(base + " --only long --long-seconds 2 --window-seconds 1 --precision bf16 --out " + q(p.dir / "eval-bf16"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto bf = nlohmann::json::parse(read_file(p.dir / "eval-bf16" / "eval.json"));
  EXPECT_EQ(bf["precision"], cpu_has_bf16() ? "bf16" : "fp32");
  EXPECT_EQ(bf["long_rollout"]["frames"].get<int>(), 13);
  EXPECT_EQ(bf["long_rollout"]["real_copy_rate"].get<double>(), lr["real_copy_rate"].get<double>());
  for (const auto& w : bf["long_rollout"]["windows"]) {
    EXPECT_GE(w["copy_rate"].get<double>(), 0.0);
    EXPECT_LE(w["copy_rate"].get<double>(), 1.0);
  }

  // --text-from-prompts: text control continues held-out procedural daytime drives, prompting only weather and time
  // of day (a drive's traffic lights are its own), and reads back the generated frames.
  const fs::path daytime = p.dir / "daytime-tokens";  // the tiny drives, every one of them by day
  copy_tokens_with(p.tokens, daytime, [](nlohmann::json& j) { j["time_of_day"] = "day"; });
  r = test::run_gaia("eval " + q(daytime) + " --world " + q(p.trained) + " --tokenizer " + q(p.tok / "tokenizer.safetensors") +
                     " --dynamics-probe " + q(models / "probe-dynamics.safetensors") + " --scene-probe " +
                     q(models / "probe-scene.safetensors") + p.tiny() + " --only text --text-from-prompts --prompt-frames 2 --text-frames 1 --futures 2 --scales 2 --out " +
                     q(p.dir / "eval-text-prompted"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto tp = nlohmann::json::parse(read_file(p.dir / "eval-text-prompted" / "eval.json"))["text_control"];
  EXPECT_EQ(tp["prompt_frames"].get<int>(), 2);
  EXPECT_EQ(tp["targets"].get<int>(), 7);  // 4 weathers and 3 times of day
  ASSERT_EQ(tp["prompt_episodes"].size(), 2u);
  for (const auto& id : tp["prompt_episodes"]) EXPECT_EQ(id.get<std::string>().rfind("synth-", 0), 0u) << id;
  for (const auto& row : tp["runs"]) EXPECT_FALSE(row["per_target"].contains("red")) << row.dump();

  // The steering response curve: the sweep's commands replace the default ones, each with its own read-back.
  r = test::run_gaia(base + " --only action --commands sweep --prompts 1 --prompt-frames 2 --frames " + std::to_string(K - 1) +
                     " --out " + q(p.dir / "eval-sweep"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto sw = nlohmann::json::parse(read_file(p.dir / "eval-sweep" / "eval.json"))["action_control"];
  EXPECT_EQ(sw["commands"], "sweep");
  EXPECT_EQ(sw["rollouts"].get<int>(), 8);
  for (const char* c : {"right-40", "right-30", "right-20", "right-14", "right-8", "left-8", "left-20", "left-30"})
    ASSERT_TRUE(sw["per_command"].contains(c)) << c << " " << sw["per_command"].dump();
  EXPECT_NEAR(sw["per_command"]["right-14"]["commanded_curvature"].get<double>(), -0.014, 1e-12);
  EXPECT_TRUE(sw["per_command"]["right-20"]["out_of_distribution"].get<bool>());
  EXPECT_FALSE(sw["per_command"]["left-8"]["out_of_distribution"].get<bool>());
  EXPECT_FALSE(sw["per_command"].contains("straight"));

  // Bad inputs: one clear line, non-zero exit, nothing written.
  r = test::run_gaia(base + " --only action --commands zigzag --out " + q(p.dir / "bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--commands"), std::string::npos) << r.output;
  if (K > 2) {  // rollouts shorter than the dynamics probe's window cannot be read back
    r = test::run_gaia(base + " --only action --frames " + std::to_string(K - 2) + " --out " + q(p.dir / "bad"));
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.output.find("--frames must be at least " + std::to_string(K - 1)), std::string::npos) << r.output;
  }
  r = test::run_gaia(base + " --only long --long-seconds 2 --window-seconds 1 --long-rollouts 0 --out " + q(p.dir / "bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--long-rollouts: 0 is out of range: allowed [1, 1000000]"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "bad" / "eval.json"));
  r = test::run_gaia(base + " --only action,bogus --out " + q(p.dir / "bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--only: unknown part 'bogus'"), std::string::npos) << r.output;
  r = test::run_gaia("eval " + q(p.tokens) + " --world " + q(p.trained) + " --tokenizer " +
                     q(p.tok / "tokenizer.safetensors") + " --dynamics-probe " + q(models / "probe-scene.safetensors") +
                     " --scene-probe " + q(models / "probe-scene.safetensors") + p.tiny() + " --out " + q(p.dir / "bad"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("not a dynamics probe"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "bad" / "eval.json"));
}

// gaia eval on recorded footage: --prompt-footage real takes its prompts from recorded held-out episodes only, futures
// report what a realism probe reads of them beside the held-out frames, and strongly steered rollouts are read back
// by the dynamics probe and by the generated video's own ego-motion. Procedural-only data, a replay of recorded
// prompts, a probe of another kind and an unknown footage are each one error line.
TEST(EvalCli, RealPromptsAreReadForRealismAndEgoMotion) {
  auto& p = Pipeline::get();
  const fs::path models = test::source_dir() / "models";
  // The same drives as recorded footage (only their source differs): every token episode; half the frame episodes,
  // on which a realism probe is trained two steps (its numbers are not the point here, their bookkeeping is).
  const fs::path tokens = p.dir / "recorded-all-tokens", frames = p.dir / "half-recorded-ds";
  for (const auto& [from, to] : {std::pair{p.tokens, tokens}, std::pair{p.ds, frames}}) {
    fs::remove_all(to);
    fs::copy(from, to, fs::copy_options::recursive);
  }
  std::vector<std::string> real_ids, synth_ids;
  for (auto& e : fs::directory_iterator(tokens / "episodes")) {
    auto j = nlohmann::json::parse(read_file(e.path() / "episode.json"));
    j["source"] = "dashcam.mp4";
    j["time_of_day"] = "day";  // text control continues recorded daytime drives
    write_file_atomic(e.path() / "episode.json", j.dump(2));
  }
  int i = 0;
  for (auto& e : fs::directory_iterator(frames / "episodes")) {
    if (i++ % 2) {
      synth_ids.push_back(e.path().filename().string());
      continue;
    }
    auto j = nlohmann::json::parse(read_file(e.path() / "episode.json"));
    j["source"] = "dashcam.mp4";
    write_file_atomic(e.path() / "episode.json", j.dump(2));
    real_ids.push_back(e.path().filename().string());
  }
  fs::remove(frames / "split.json");
  auto r = test::run_gaia("data split " + q(frames) + " --hold-out " + real_ids[0] + " --hold-out " + synth_ids[0] + p.tiny());
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("probe train realism " + q(frames) + p.tiny() + " --steps 2 --batch-size 4 --out " + q(p.dir / "realism"));
  ASSERT_EQ(r.status, 0) << r.output;
  const fs::path realism = p.dir / "realism" / "probe-realism.safetensors";

  const int64_t K = probe::load_probe(models / "probe-dynamics.safetensors", torch::kCPU)->frames;
  const std::string base = "eval " + q(tokens) + " --world " + q(p.trained) + " --tokenizer " +
                           q(p.tok / "tokenizer.safetensors") + " --dynamics-probe " +
                           q(models / "probe-dynamics.safetensors") + " --scene-probe " +
                           q(models / "probe-scene.safetensors") + p.tiny() + " --prompts 2 --prompt-frames 2 --frames " +
                           std::to_string(K - 1) + " --prompt-footage real";
  r = test::run_gaia(base + " --only futures --futures 2 --realism-probe " + q(realism) + " --out " + q(p.dir / "eval-real"));
  ASSERT_EQ(r.status, 0) << r.output;
  auto j = nlohmann::json::parse(read_file(p.dir / "eval-real" / "eval.json"));
  EXPECT_EQ(j["prompt_footage"], "real");
  const auto& re = j["futures"]["realism"];
  EXPECT_EQ(re["generated_frames"].get<int64_t>(), 2 * 2 * (K - 1));  // prompts x futures x frames
  EXPECT_GE(re["held_out_frames"].get<int64_t>(), 1);
  for (const char* k : {"generated_read_real", "held_out_read_real", "generated_mean_p_real", "held_out_mean_p_real"}) {
    EXPECT_GE(re[k].get<double>(), 0.0) << k;
    EXPECT_LE(re[k].get<double>(), 1.0) << k;
  }

  r = test::run_gaia(base + " --only action --out " + q(p.dir / "eval-real-action"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto a = nlohmann::json::parse(read_file(p.dir / "eval-real-action" / "eval.json"))["action_control"];
  EXPECT_EQ(a["strong_steering"]["rollouts"].get<int>(), 2 * 2);  // strong-left and strong-right from each prompt
  for (const char* k : {"probe_sign_accuracy", "ego_motion_sign_accuracy", "ego_motion_read"}) {
    EXPECT_GE(a["strong_steering"][k].get<double>(), 0.0) << k;
    EXPECT_LE(a["strong_steering"][k].get<double>(), 1.0) << k;
  }
  const auto yaw = a["ego_motion"]["yaw_rate_by_rollout"];
  ASSERT_EQ(yaw.size(), size_t(a["rollouts"].get<int>()));
  int read = 0;
  for (const auto& y : yaw) read += y.is_number() && std::isfinite(y.get<double>());
  EXPECT_EQ(a["ego_motion"]["rollouts_read"].get<int>(), read);

  // Text control from real prompts: held-out recorded daytime drives continued under weather and time-of-day
  // prompts (no traffic lights: recorded drives have none labelled); the generated frames alone are read.
  r = test::run_gaia(base + " --only text --futures 2 --text-frames 1 --scales 0,2 --out " + q(p.dir / "eval-real-text"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto t = nlohmann::json::parse(read_file(p.dir / "eval-real-text" / "eval.json"))["text_control"];
  EXPECT_EQ(t["prompt_frames"].get<int>(), 2);
  EXPECT_EQ(t["targets"].get<int>(), 7);  // 4 weathers, 3 times of day
  ASSERT_EQ(t["prompt_episodes"].size(), 2u);
  for (const auto& row : t["runs"]) {
    EXPECT_FALSE(row.contains("light")) << row.dump();
    EXPECT_EQ(row["per_target"].size(), 7u) << row.dump();
    for (const char* k : {"weather", "time_of_day"}) {
      EXPECT_GE(row[k].get<double>(), 0.0) << k;
      EXPECT_LE(row[k].get<double>(), 1.0) << k;
    }
  }

  // world eval --footage: the held-out recorded episodes scored, the same windows as with any footage; none in a
  // dataset of procedural drives only.
  auto world_eval = [&](const fs::path& t, const std::string& footage) {
    return test::run_gaia("world eval " + q(t) + " --world " + q(p.trained) + p.tiny() +
                          " --max-windows 2 --sweep-windows 1 --footage " + footage);
  };
  r = world_eval(tokens, "real");
  ASSERT_EQ(r.status, 0) << r.output;
  auto we = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  EXPECT_EQ(we["footage"], "real");
  EXPECT_GE(we["episodes"].get<int>(), 1);
  r = world_eval(tokens, "any");
  ASSERT_EQ(r.status, 0) << r.output;
  auto any = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  EXPECT_EQ(any["episodes"], we["episodes"]);
  EXPECT_EQ(any["bits_per_token"]["world_model"], we["bits_per_token"]["world_model"]);
  r = world_eval(p.tokens, "real");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("no held-out real window"), std::string::npos) << r.output;

  // Bad inputs: one line naming what is wrong, nothing written.
  r = test::run_gaia(base + " " + q(p.ds) + " --only action --out " + q(p.dir / "bad-real"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("give --prompt-footage procedural"), std::string::npos) << r.output;
  r = test::run_gaia("eval " + q(p.tokens) + " --world " + q(p.trained) + " --tokenizer " + q(p.tok / "tokenizer.safetensors") +
                     " --dynamics-probe " + q(models / "probe-dynamics.safetensors") + " --scene-probe " +
                     q(models / "probe-scene.safetensors") + p.tiny() + " --only futures --prompt-footage real --out " +
                     q(p.dir / "bad-real"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("no held-out real episode"), std::string::npos) << r.output;
  r = test::run_gaia(base + " --only futures --realism-probe " + q(models / "probe-scene.safetensors") + " --out " +
                     q(p.dir / "bad-real"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("not a realism probe"), std::string::npos) << r.output;
  r = test::run_gaia(base + " --only futures --prompt-footage sideways --out " + q(p.dir / "bad-real"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--prompt-footage"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p.dir / "bad-real" / "eval.json"));
}

// gaia sim --stdio: a session made from an episode of the token dataset and stepped with `generate`'s command gives
// `generate`'s tokens (same seed, guidance and sampling from the weights); frames come back as PNG through the
// tokenizer; every line gets one answer line, bad ones a 4xx, and the session keeps serving.
TEST(SimCli, StdioSessionsGiveTheTokensOfGenerateAndAnswerEveryLine) {
  auto& p = Pipeline::get();
  auto r = test::run_gaia("generate " + q(p.tokens) + " --world " + q(p.trained) + p.tiny() +
                          " --episode 0 --prompt-frames 2 --frames 3 --steer left --speed 8 --seed 5 --out " +
                          q(p.dir / "gen-sim"));
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile rollout(p.dir / "gen-sim" / "rollout.safetensors");
  const auto t = tensor_from_view(rollout.get("tokens")).to(torch::kFloat).reshape({-1});  // [1, 5, h, w]
  const std::vector<float> expected(t.data_ptr<float>(), t.data_ptr<float>() + t.numel());
  const fs::path requests = p.dir / "sim-requests.jsonl";
  write_file_atomic(requests,
                    "{\"op\": \"create\", \"prompt\": {\"episode\": 0, \"frames\": 2}, \"seed\": 5}\n"
                    "{\"op\": \"step\", \"session\": 1, \"speed\": 8, \"curvature\": 0.01}\n"
                    "not json\n"
                    "{\"op\": \"step\", \"session\": 1, \"speed\": 8, \"curvature\": 0.01, \"frame\": true}\n"
                    "{\"op\": \"step\", \"session\": 7}\n"
                    "{\"op\": \"create\", \"prompt\": {\"episode\": \"nowhere\"}}\n"
                    "{\"op\": \"step\", \"session\": 1, \"speed\": 8, \"curvature\": 0.01, \"frame\": \"jpeg\"}\n");
  r = test::run_shell(test::gaia_command("sim " + q(p.tokens) + " --world " + q(p.trained) + " --tokenizer " +
                                         q(p.tok / "tokenizer.safetensors") + p.tiny() + " --stdio") +
                      " < " + q(requests) + " 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  std::vector<nlohmann::json> answers;
  std::istringstream lines(r.output);
  for (std::string line; std::getline(lines, line);) answers.push_back(nlohmann::json::parse(line));
  ASSERT_EQ(answers.size(), 7u) << r.output;
  const std::vector<int> statuses = {200, 200, 400, 200, 404, 400, 200};
  for (size_t i = 0; i < answers.size(); ++i) EXPECT_EQ(answers[i]["status"], statuses[i]) << answers[i].dump();
  EXPECT_EQ(answers[0]["steps"], 2);
  EXPECT_NE(answers[5]["error"].get<std::string>().find("nowhere"), std::string::npos);
  EXPECT_EQ(answers[3]["frame"].get<std::string>().rfind("data:image/png;base64,", 0), 0u);
  EXPECT_EQ(answers[6]["frame"].get<std::string>().rfind("data:image/jpeg;base64,/9j/", 0), 0u);  // a JPEG's magic
  const size_t n = expected.size() / 5;
  size_t k = 2;
  for (size_t i : {1, 3, 6}) {
    auto got = answers[i]["tokens"].get<std::vector<int64_t>>();
    ASSERT_EQ(got.size(), n);
    for (size_t j = 0; j < n; ++j) EXPECT_EQ(double(got[j]), expected[k * n + j]) << "step " << k << " token " << j;
    EXPECT_EQ(answers[i]["step"], k);
    ++k;
  }
  auto no = test::run_gaia("sim --world " + q(p.trained) + p.tiny());
  EXPECT_NE(no.status, 0);
  EXPECT_NE(no.output.find("--stdio"), std::string::npos) << no.output;
}

// --precision bf16 reaches the sessions: gaia sim gives gaia generate's tokens at bf16 (the fused token step with bf16
// matrices on both), and a CPU without bf16 instructions runs both in fp32, saying so.
TEST(SimCli, Bf16SessionsGiveTheTokensOfGenerateAtBf16) {
  auto& p = Pipeline::get();
  const std::string bf16 = " --precision bf16";
  auto r = test::run_gaia("generate " + q(p.tokens) + " --world " + q(p.trained) + p.tiny() + bf16 +
                          " --episode 0 --prompt-frames 2 --frames 3 --steer left --speed 8 --seed 5 --out " +
                          q(p.dir / "gen-sim-bf16"));
  ASSERT_EQ(r.status, 0) << r.output;
  const bool fallback = r.output.find("running in fp32 instead") != std::string::npos;
  EXPECT_EQ(fallback, !cpu_has_bf16()) << r.output;
  SafetensorsFile rollout(p.dir / "gen-sim-bf16" / "rollout.safetensors");
  const auto want = tensor_from_view(rollout.get("tokens")).to(torch::kLong).reshape({5, -1});
  const fs::path requests = p.dir / "sim-bf16.jsonl";
  std::string lines = "{\"op\": \"create\", \"prompt\": {\"episode\": 0, \"frames\": 2}, \"seed\": 5}\n";
  for (int i = 0; i < 3; ++i) lines += "{\"op\": \"step\", \"session\": 1, \"speed\": 8, \"curvature\": 0.01}\n";
  write_file_atomic(requests, lines);
  r = test::run_shell(test::gaia_command("sim " + q(p.tokens) + " --world " + q(p.trained) + p.tiny() + bf16 +
                                         " --stdio") + " < " + q(requests) + " 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(r.output.find("running in fp32 instead") != std::string::npos, fallback) << r.output;
  std::vector<nlohmann::json> answers;
  std::istringstream in(r.output);
  for (std::string line; std::getline(in, line);)
    if (!line.empty() && line[0] == '{') answers.push_back(nlohmann::json::parse(line));
  ASSERT_EQ(answers.size(), 4u) << r.output;
  for (int64_t k = 2; k < 5; ++k) {
    const auto got = answers[size_t(k - 1)]["tokens"].get<std::vector<int64_t>>();
    ASSERT_EQ(int64_t(got.size()), want.size(1));
    EXPECT_TRUE(torch::equal(torch::tensor(got), want[k])) << "step " << k;
  }
}

// gaia sim --video: a video file tokenized at start is a prompt by its name, and a session from it stepped with
// `generate --video`'s command gives generate's tokens; a name it does not have is a 400 naming the ones it has, and
// --video without --tokenizer is refused.
TEST(SimCli, AVideoFileIsAPromptByItsName) {
  auto& p = Pipeline::get();
  const fs::path video = p.dir / "drive.mp4";
  {
    data::Dataset ds(p.ds);
    auto set = data::frame_set(ds, {ds.ids().front()}, 0, 0);
    std::vector<cv::Mat> frames;
    for (auto& f : set.frames) frames.push_back(set.episodes[f.episode]->frame_bgr(f.frame));
    data::write_video(video, frames, 25);
  }
  const std::string tok = " --tokenizer " + q(p.tok / "tokenizer.safetensors");
  auto r = test::run_gaia("generate --video " + q(video) + " --world " + q(p.trained) + tok + p.tiny() +
                          " --prompt-frames 2 --frames 3 --steer left --speed 8 --seed 5 --out " + q(p.dir / "gen-video"));
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile rollout(p.dir / "gen-video" / "rollout.safetensors");
  const auto t = tensor_from_view(rollout.get("tokens")).to(torch::kLong).reshape({5, -1});
  const fs::path requests = p.dir / "sim-video.jsonl";
  write_file_atomic(requests,
                    "{\"op\": \"create\", \"prompt\": {\"episode\": \"drive\", \"frames\": 2}, \"seed\": 5}\n"
                    "{\"op\": \"step\", \"session\": 1, \"speed\": 8, \"curvature\": 0.01}\n"
                    "{\"op\": \"step\", \"session\": 1, \"speed\": 8, \"curvature\": 0.01}\n"
                    "{\"op\": \"create\", \"prompt\": {\"episode\": \"elsewhere\"}}\n");
  r = test::run_shell(test::gaia_command("sim --video " + q(video) + " --world " + q(p.trained) + tok + p.tiny() +
                                         " --stdio") + " < " + q(requests) + " 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  std::vector<nlohmann::json> answers;
  std::istringstream lines(r.output);
  for (std::string line; std::getline(lines, line);)
    if (!line.empty() && line[0] == '{') answers.push_back(nlohmann::json::parse(line));
  ASSERT_EQ(answers.size(), 4u) << r.output;
  EXPECT_NE(r.output.find("video prompt 'drive'"), std::string::npos) << r.output;
  EXPECT_EQ(answers[0]["status"], 200) << answers[0].dump();
  EXPECT_EQ(answers[0]["prompt_frames"], 2);
  for (int64_t k = 2; k < 4; ++k) {
    ASSERT_EQ(answers[size_t(k - 1)]["status"], 200) << answers[size_t(k - 1)].dump();
    auto got = answers[size_t(k - 1)]["tokens"].get<std::vector<int64_t>>();
    EXPECT_EQ(got, std::vector<int64_t>(t[k].data_ptr<int64_t>(), t[k].data_ptr<int64_t>() + t.size(1))) << "step " << k;
  }
  EXPECT_EQ(answers[3]["status"], 400);
  EXPECT_NE(answers[3]["error"].get<std::string>().find("video prompts are drive"), std::string::npos) << answers[3];
  r = test::run_gaia("sim --video " + q(video) + " --world " + q(p.trained) + p.tiny() + " --stdio < /dev/null");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--video needs --tokenizer"), std::string::npos) << r.output;
}
