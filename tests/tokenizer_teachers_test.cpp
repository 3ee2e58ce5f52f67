// The tokenizer's teacher losses (§2.2, §4.1) in training, with the small teacher fixtures of
// tools/make_teacher_fixtures.py: the perceptual (VGG16) and DINO terms are in the loss at the config's weights, their
// gradients reach the parts of the tokenizer they should and no others, the teachers stay frozen, resuming is exact
// with both on, the paper's weights are the defaults, and a named teacher file that does not exist is an error.
#include <map>
#include <set>

#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/core/safetensors.h"
#include "gaia/tokenizer/teachers.h"
#include "gaia/tokenizer/trainer.h"
#include "gaia/torch/tensor_io.h"
#include "test_util.h"

using namespace gaia;

namespace {

using Weights = std::map<std::string, torch::Tensor>;

fs::path fixture(const std::string& file) { return test::source_dir() / "tests" / "fixtures" / file; }

Weights read_weights(const fs::path& file) {
  SafetensorsFile f(file);
  Weights w;
  for (const auto& n : f.names()) w[n] = tensor_from_view(f.get(n));
  return w;
}

// The tensors of `after` that differ from `before` by at least one bit (every one of them must be in `before`).
std::set<std::string> moved(const Weights& before, const Weights& after) {
  std::set<std::string> out;
  for (const auto& [n, t] : after) {
    EXPECT_TRUE(before.count(n)) << n;
    if (before.count(n) && !torch::equal(before.at(n), t)) out.insert(n);
  }
  return out;
}

// The names in `w` that start with one of `prefixes`.
std::set<std::string> named(const Weights& w, const std::vector<std::string>& prefixes) {
  std::set<std::string> out;
  for (const auto& [n, t] : w)
    for (const auto& p : prefixes)
      if (n.rfind(p, 0) == 0) out.insert(n);
  return out;
}

Config teachers_config() {
  Config c = test::config("tiny.yaml");
  c.tokenizer.disc_start = 1000000;  // the GAN term is not the subject here (the resume test turns it on)
  return c;
}

// Every loss weight 0 (the test turns one teacher's on), no weight decay, no warm-up: one AdamW step then moves a
// tensor by a bit exactly when the weighted terms' gradient reaches it.
Config isolated() {
  Config c = teachers_config();
  auto& t = c.tokenizer;
  t.w_l1 = t.w_l2 = t.w_perceptual = t.w_gan = t.w_codebook = t.w_dino = 0;
  t.weight_decay = 0;
  t.warmup_steps = 0;
  t.lr = t.final_lr = 1e-3;
  return c;
}

// A tiny dataset (two episodes of 5 frames: one trains, one validates) in a scratch directory.
struct Scratch {
  test::TempDir dir;
  Scratch() { test::synth_dataset(dir / "ds", 2, 0.2); }

  tokenizer::TrainOptions options(const std::string& out, int steps, const fs::path& vgg = {}, const fs::path& dino = {}) {
    tokenizer::TrainOptions o;
    o.dataset = dir / "ds";
    o.out = dir / out;
    o.steps = steps;
    o.val_every = 1000;
    o.val_frames = 4;
    o.restart_every = 0;
    o.vgg = vgg;
    o.dino = dino;
    return o;
  }
};

struct TrainRun {
  tokenizer::TrainResult result;
  std::vector<nlohmann::json> losses;  // each step's loss terms, as on_step reports them
  Weights weights;                     // OUT/tokenizer.safetensors when the run finished
};

TrainRun run_training(const Config& c, const tokenizer::TrainOptions& o) {
  TrainRun r;
  r.result = tokenizer::train_tokenizer(c, o, [&](const tokenizer::StepLog& l) { r.losses.push_back(l.losses); });
  if (fs::exists(o.out / "tokenizer.safetensors")) r.weights = read_weights(o.out / "tokenizer.safetensors");
  return r;
}

// The trainer's total from its own breakdown (no GAN term): L1, L2, codebook + commitment (equal in value), and the
// teacher terms that are present.
double recomputed_total(const TokenizerConfig& t, const nlohmann::json& l) {
  return t.w_l1 * l["l1"].get<double>() + t.w_l2 * l["l2"].get<double>() +
         t.w_codebook * (1 + t.commitment) * l["codebook"].get<double>() +
         t.w_perceptual * l.value("perceptual", 0.0) + t.w_dino * l.value("dino", 0.0);
}

bool has_note(const tokenizer::TrainResult& r, const std::string& text) {
  for (const auto& n : r.notes)
    if (n.find(text) != std::string::npos) return true;
  return false;
}

}  // namespace

TEST(TokenizerTeachers, PerceptualTermIsInTheLossAtItsWeight) {
  Scratch s;
  const Config c = teachers_config();
  ASSERT_EQ(c.tokenizer.w_perceptual, 0.1);  // §4.1, from the defaults (tiny.yaml does not set it)
  const TrainRun plain = run_training(c, s.options("plain", 3));
  const TrainRun taught = run_training(c, s.options("vgg", 3, fixture("vgg16_narrow.safetensors")));
  EXPECT_TRUE(has_note(plain.result, "perceptual loss off"));
  EXPECT_FALSE(has_note(taught.result, "perceptual loss off"));
  ASSERT_EQ(plain.losses.size(), 3u);
  ASSERT_EQ(taught.losses.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const auto& l = taught.losses[i];
    EXPECT_FALSE(plain.losses[i].contains("perceptual")) << i;
    EXPECT_FALSE(l.contains("dino")) << i;
    ASSERT_TRUE(l.contains("perceptual")) << i;
    const double p = l["perceptual"].get<double>(), total = l["loss"].get<double>();
    EXPECT_TRUE(std::isfinite(p) && p > 0) << i << ": " << p;
    EXPECT_NEAR(total, recomputed_total(c.tokenizer, l), 2e-6 * total) << i;
  }
  // Step 1 sees the same weights and frames with and without the teacher: every other term is the same, and the
  // totals differ by exactly w_perceptual x the term.
  const auto &a = plain.losses[0], &b = taught.losses[0];
  for (const char* k : {"l1", "l2", "codebook"}) EXPECT_EQ(a[k].get<double>(), b[k].get<double>()) << k;
  EXPECT_NEAR(b["loss"].get<double>() - a["loss"].get<double>(), 0.1 * b["perceptual"].get<double>(),
              2e-6 * b["loss"].get<double>());
  // metrics.jsonl logs the same term.
  const std::string log = read_file(s.dir / "vgg" / "metrics.jsonl");
  const auto last = nlohmann::json::parse(log.substr(log.rfind('\n', log.size() - 2) + 1));
  EXPECT_EQ(last["losses"]["perceptual"].get<double>(), taught.losses[2]["perceptual"].get<double>());
  // and it changes what is learnt.
  EXPECT_FALSE(moved(plain.weights, taught.weights).empty());
}

// The perceptual term compares the reconstruction with the frame: its gradient reaches the decoder and, through the
// straight-through quantiser (proj_out, proj_in), the encoder; the codebook is moved only by the codebook loss.
TEST(TokenizerTeachers, PerceptualGradientReachesTheDecoderAndThroughTheQuantiserTheEncoder) {
  Scratch s;
  const fs::path vgg = fixture("vgg16_narrow.safetensors");
  Config frozen = isolated();
  frozen.tokenizer.lr = frozen.tokenizer.final_lr = 0;
  const Weights start = run_training(frozen, s.options("start", 1, vgg)).weights;
  // Without a term to learn from, nothing moves: the control.
  Config c = isolated();
  EXPECT_TRUE(moved(start, run_training(c, s.options("none", 1, vgg)).weights).empty());
  c.tokenizer.w_perceptual = 0.5;  // not the default: the config's weight is the one used
  const TrainRun r = run_training(c, s.options("vgg", 1, vgg));
  ASSERT_EQ(r.losses.size(), 1u);
  EXPECT_NEAR(r.losses[0]["loss"].get<double>(), 0.5 * r.losses[0]["perceptual"].get<double>(),
              1e-6 * r.losses[0]["loss"].get<double>());
  const auto m = moved(start, r.weights);
  const auto reached = named(start, {"decoder.", "encoder.", "quantizer.proj_in.", "quantizer.proj_out."});
  EXPECT_GT(named(start, {"decoder."}).size(), 10u);
  EXPECT_EQ(m, reached);
  EXPECT_FALSE(m.count("quantizer.codebook.weight"));
}

// The DINO term regresses the teacher's features from the codes through a linear head: its gradient reaches the head,
// the code projection and the encoder, and not the decoder (nor proj_out or the codebook). The torchvision and timm
// fixtures hold the same weights, so both layouts train to the same bits.
TEST(TokenizerTeachers, DinoGradientReachesTheEncoderAndHeadNotTheDecoder) {
  Scratch s;
  const fs::path timm = fixture("vit_timm.safetensors"), tv = fixture("vit_tv.safetensors");
  Config frozen = isolated();
  frozen.tokenizer.lr = frozen.tokenizer.final_lr = 0;
  const Weights start = run_training(frozen, s.options("start", 1, {}, timm)).weights;
  ASSERT_TRUE(start.count("dino_head.weight"));
  EXPECT_EQ(start.at("dino_head.weight").size(0), 16);  // the fixture ViT's width
  Config c = isolated();
  EXPECT_TRUE(moved(start, run_training(c, s.options("none", 1, {}, timm)).weights).empty());
  c.tokenizer.w_dino = 0.5;
  const TrainRun r = run_training(c, s.options("timm", 1, {}, timm));
  ASSERT_EQ(r.losses.size(), 1u);
  const double d = r.losses[0]["dino"].get<double>();
  EXPECT_TRUE(std::isfinite(d) && d > 0 && d <= 2) << d;  // 1 - cosine similarity
  EXPECT_NEAR(r.losses[0]["loss"].get<double>(), 0.5 * d, 1e-6 * d);
  EXPECT_EQ(moved(start, r.weights), named(start, {"encoder.", "quantizer.proj_in.", "dino_head."}));
  const TrainRun r_tv = run_training(c, s.options("tv", 1, {}, tv));
  EXPECT_EQ(r_tv.losses[0]["dino"].get<double>(), d);
  EXPECT_TRUE(moved(r.weights, r_tv.weights).empty());
}

TEST(TokenizerTeachers, DinoTermIsInTheLossAtItsWeight) {
  Scratch s;
  const Config c = teachers_config();
  ASSERT_EQ(c.tokenizer.w_dino, 0.1);  // §4.1, from the defaults
  const TrainRun plain = run_training(c, s.options("plain", 2));
  const TrainRun taught = run_training(c, s.options("dino", 2, {}, fixture("vit_timm.safetensors")));
  EXPECT_TRUE(has_note(plain.result, "DINO distillation loss off"));
  EXPECT_FALSE(has_note(taught.result, "DINO distillation loss off"));
  ASSERT_EQ(taught.losses.size(), 2u);
  for (const auto& l : taught.losses) {
    ASSERT_TRUE(l.contains("dino"));
    EXPECT_NEAR(l["loss"].get<double>(), recomputed_total(c.tokenizer, l), 2e-6 * l["loss"].get<double>());
  }
  EXPECT_NEAR(taught.losses[0]["loss"].get<double>() - plain.losses[0]["loss"].get<double>(),
              0.1 * taught.losses[0]["dino"].get<double>(), 2e-6 * taught.losses[0]["loss"].get<double>());
  EXPECT_FALSE(plain.weights.count("dino_head.weight"));
}

// The teachers are frozen: no parameter asks for a gradient or gets one, and they are in eval mode; the gradient of
// both terms still reaches the image they look at.
TEST(TokenizerTeachers, TeachersAreFrozenAndPassTheGradientToTheirInput) {
  tokenizer::Vgg16 vgg(fixture("vgg16_narrow.safetensors"));
  tokenizer::DinoViT vit(fixture("vit_tv.safetensors"));
  torch::manual_seed(3);
  auto x = (torch::rand({2, 3, 32, 64}) * 2 - 1).requires_grad_();
  auto y = torch::rand({2, 3, 32, 64}) * 2 - 1;
  (tokenizer::perceptual_loss(vgg, x, y) + vit->forward(x).pow(2).mean()).backward();
  ASSERT_TRUE(x.grad().defined());
  EXPECT_GT(x.grad().abs().sum().item<double>(), 0);
  for (torch::nn::Module* m : {static_cast<torch::nn::Module*>(vgg.ptr().get()), static_cast<torch::nn::Module*>(vit.ptr().get())}) {
    EXPECT_FALSE(m->is_training());
    ASSERT_FALSE(m->parameters().empty());
    for (const auto& p : m->named_parameters()) {
      EXPECT_FALSE(p.value().requires_grad()) << p.key();
      EXPECT_FALSE(p.value().grad().defined()) << p.key();
    }
  }
}

// Both teachers, the GAN term and dead-code restarts on: stopped half-way and resumed, the run ends with the same
// bits as a straight one, and the resumed steps log the same loss terms.
TEST(TokenizerTeachers, ResumeIsExactWithBothTeachers) {
  Scratch s;
  Config c = teachers_config();
  c.tokenizer.disc_start = 2;
  const fs::path vgg = fixture("vgg16_narrow.safetensors"), dino = fixture("vit_timm.safetensors");
  auto o = s.options("straight", 6, vgg, dino);
  o.restart_every = 2;
  const TrainRun straight = run_training(c, o);
  o.out = s.dir / "resumed";
  o.stop_after = 3;
  const TrainRun first = run_training(c, o);
  EXPECT_EQ(first.result.final_step, 3);
  EXPECT_TRUE(first.weights.empty());
  o.stop_after = -1;
  const TrainRun second = run_training(c, o);
  EXPECT_TRUE(second.result.resumed);
  ASSERT_EQ(straight.losses.size(), 6u);
  ASSERT_EQ(second.losses.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_TRUE(straight.losses[3 + i].contains("gan_g"));
    EXPECT_EQ(straight.losses[3 + i].dump(), second.losses[i].dump()) << "step " << 4 + i;
  }
  ASSERT_TRUE(straight.weights.count("dino_head.weight"));
  ASSERT_EQ(straight.weights.size(), second.weights.size());
  EXPECT_TRUE(moved(straight.weights, second.weights).empty());
}

// §4.1: lambda_L1 0.2, lambda_L2 2.0, lambda_perceptual 0.1, lambda_GAN 1.0, lambda_codebook 1.0, lambda_DINO 0.1 are
// the built-in defaults, and no shipped config sets them to anything else.
TEST(TokenizerTeachers, PaperLossWeightsAreTheDefaultsInEveryShippedConfig) {
  std::vector<TokenizerConfig> configs{TokenizerConfig{}};
  for (const auto& e : fs::directory_iterator(test::source_dir() / "configs"))
    if (e.path().extension() == ".yaml") configs.push_back(Config::load(e.path()).tokenizer);
  EXPECT_GE(configs.size(), 4u);  // the defaults, tiny, default, paper
  for (const auto& t : configs) {
    EXPECT_EQ(t.w_l1, 0.2);
    EXPECT_EQ(t.w_l2, 2.0);
    EXPECT_EQ(t.w_perceptual, 0.1);
    EXPECT_EQ(t.w_gan, 1.0);
    EXPECT_EQ(t.w_codebook, 1.0);
    EXPECT_EQ(t.w_dino, 0.1);
  }
}

// A teacher the caller names must exist: a mistyped path is an error naming it, before the run directory is made,
// not a long run without the loss that was asked for.
TEST(TokenizerTeachers, NamedTeacherFileThatDoesNotExistIsAnError) {
  Scratch s;
  const Config c = teachers_config();
  for (const bool decoder_only : {false, true}) {
    auto o = s.options("run", 1, s.dir / "vgg-typo.safetensors");
    o.decoder_only = decoder_only;
    std::string err = test::error_of([&] { tokenizer::train_tokenizer(c, o); });
    EXPECT_NE(err.find("vgg-typo.safetensors: no such VGG16 weights file"), std::string::npos) << err;
    o = s.options("run", 1, {}, s.dir / "dino-typo.safetensors");
    o.decoder_only = decoder_only;
    err = test::error_of([&] { tokenizer::train_tokenizer(c, o); });
    EXPECT_NE(err.find("dino-typo.safetensors: no such DINO ViT weights file"), std::string::npos) << err;
  }
  EXPECT_FALSE(fs::exists(s.dir / "run"));
  // A file in the other teacher's layout is an error naming the tensor it lacks.
  auto o = s.options("run", 1, fixture("vit_timm.safetensors"));
  const std::string err = test::error_of([&] { tokenizer::train_tokenizer(c, o); });
  EXPECT_NE(err.find("features.0.weight"), std::string::npos) << err;
}

TEST(TokenizerTeachersCli, MistypedVggPathFailsNamingIt) {
  Scratch s;
  const auto r = test::run_gaia("tokenizer train " + test::q(s.dir / "ds") + " --config " +
                                test::q(test::source_dir() / "configs" / "tiny.yaml") + " --vgg " +
                                test::q(s.dir / "vgg-typo.safetensors") + " --steps 1 --out " + test::q(s.dir / "run"));
  EXPECT_NE(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("vgg-typo.safetensors: no such VGG16 weights file"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(s.dir / "run"));
}
