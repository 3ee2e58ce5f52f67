// World model (§2.1, §2.3, §5.1): causality, loss placement, KV cache = full forward, sliding window, guidance,
// sampling strategies, parameter count against the plan, and bad prompts.
#include <optional>
#include <set>

#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/sizing/sizing.h"
#include "gaia/train/checkpoint.h"
#include "gaia/world/calibrate.h"
#include "gaia/world/distill.h"
#include "gaia/torch/precision.h"
#include "gaia/world/guidance.h"
#include "gaia/world/model.h"
#include "gaia/world/rollout.h"
#include "gaia/world/sampling.h"
#include "gaia/world/token_step.h"
#include "gaia/world/transformer.h"
#include "test_util.h"

using namespace gaia;
using namespace gaia::world;

namespace {


constexpr int64_t kModelN = 6, kModelK = 32;

// On GAIA_TEST_DEVICE (scripts/gpu-check.sh: CUDA), with its batches.
WorldModel small_model(const Config& c, uint64_t seed = 0) {
  torch::manual_seed(seed);
  WorldModel m(c.world, kModelN, kModelK);
  m->to(torch::Device(test::device_name()));
  m->eval();
  return m;
}

WorldBatch random_batch(const Config& c, int64_t B, int64_t T, uint64_t seed = 1) {
  torch::manual_seed(seed);
  WorldBatch b;
  b.tokens = torch::randint(0, kModelK, {B, T, kModelN}, torch::kLong);
  b.actions = torch::randn({B, T, 2});
  b.text_ids = torch::randint(0, c.world.text_vocab, {B, T, c.world.text_tokens}, torch::kLong);
  return b.to(torch::Device(test::device_name()));
}

}  // namespace

TEST(WorldModel, LogitsAreCausal) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c);
  torch::NoGradGuard ng;
  auto b = random_batch(c, 1, 3);
  auto base = m->forward(b);  // [1, 3, n, K]
  // Change image token z_{1,2}: logits of every token predicted before it stay, the ones after it move.
  auto b2 = b;
  b2.tokens = b.tokens.clone();
  b2.tokens[0][1][2] = (b.tokens[0][1][2].item<int64_t>() + 1) % kModelK;
  auto changed = m->forward(b2);
  const auto& L = m->layout;
  const int64_t pos = L.flat(1, L.image_slot(2));
  for (int64_t t = 0; t < 3; ++t)
    for (int64_t i = 0; i < kModelN; ++i) {
      bool same = torch::allclose(base[0][t][i], changed[0][t][i], 0, 0);
      if (L.predictor(t, i) < pos) EXPECT_TRUE(same) << "t " << t << " i " << i;
      else EXPECT_FALSE(same) << "t " << t << " i " << i;
    }
  // Actions of step 1 come after its image: they change step 2 only.
  auto b3 = b;
  b3.actions = b.actions.clone();
  b3.actions[0][1][1] += 1.0;
  auto a = m->forward(b3);
  EXPECT_TRUE(torch::equal(a.narrow(1, 0, 2), base.narrow(1, 0, 2)));
  EXPECT_FALSE(torch::allclose(a[0][2], base[0][2]));
}

TEST(WorldModel, LossIsOnImageTokensOnly) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c);
  torch::NoGradGuard ng;
  auto b = random_batch(c, 2, 2);
  auto logits = m->forward(b);
  ASSERT_EQ(logits.sizes(), (std::vector<int64_t>{2, 2, kModelN, kModelK}));
  // The same numbers from the head over every position, gathered at the image-token predictors by hand.
  auto all = m->logits(m->body(m->embed(b)));  // [B, T * S, K]
  double manual = 0;
  const auto& L = m->layout;
  for (int64_t bb = 0; bb < 2; ++bb)
    for (int64_t t = 0; t < 2; ++t)
      for (int64_t i = 0; i < kModelN; ++i) {
        auto lp = torch::log_softmax(all[bb][L.predictor(t, i)], -1);
        manual -= lp[b.tokens[bb][t][i].item<int64_t>()].item<double>();
      }
  manual /= 2 * 2 * kModelN;
  EXPECT_NEAR(image_token_loss(logits, b.tokens).item<double>(), manual, 1e-5);
  // A random model starts near log K.
  EXPECT_NEAR(manual, std::log(double(kModelK)), 0.5);
}

TEST(WorldModel, KvCacheMatchesFullForward) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c);
  torch::NoGradGuard ng;
  auto b = random_batch(c, 2, c.world.context_steps);
  auto x = m->embed(b);  // [B, L, d]
  auto full = m->logits(m->body(x));
  auto cache = m->make_cache(2, m->layout.length());
  std::vector<torch::Tensor> parts;
  // Feed in uneven chunks (1 token, then 3, then the rest one by one) as the sampler does.
  int64_t p = 0;
  for (int64_t len : {int64_t(1), int64_t(3)}) {
    parts.push_back(m->logits(m->body(x.narrow(1, p, len), &cache)));
    p += len;
  }
  for (; p < x.size(1); ++p) parts.push_back(m->logits(m->body(x.narrow(1, p, 1), &cache)));
  auto inc = torch::cat(parts, 1);
  EXPECT_EQ(cache.length, x.size(1));
  EXPECT_LT((inc - full).abs().max().item<double>(), 1e-4);
  // The fused one-token attention against the general path, token by token on the same cache contents.
  auto general = m->make_cache(2, m->layout.length());
  general.fused_single_token = false;
  cache.reset();
  std::vector<torch::Tensor> a, g;
  for (p = 0; p < x.size(1); ++p) {
    a.push_back(m->logits(m->body(x.narrow(1, p, 1), &cache)));
    g.push_back(m->logits(m->body(x.narrow(1, p, 1), &general)));
  }
  EXPECT_LT((torch::cat(a, 1) - torch::cat(g, 1)).abs().max().item<double>(), 1e-5);
}

// Weights large enough that attention and the MLPs are far from uniform (a new model's are near zero).
static void sharpen(WorldModel& m, double by = 6.0) {
  torch::NoGradGuard ng;
  for (auto& p : m->parameters()) p.mul_(by);
}

// prefill() as the body with a cache: the same keys and values in every layer (the last block stops at them), from
// a cache already holding a prefix; long appends attend block by block (transformer.cpp), checked against the
// uncached causal forward.
TEST(WorldModel, PrefillFillsTheCacheAsTheBodyDoes) {
  Config c = test::config("tiny.yaml");
  c.world.context_steps = 8;
  torch::manual_seed(3);
  WorldModel m(c.world, /*n=*/60, kModelK);  // 8 steps x 64 slots: 512 positions, appends past the query block
  m->to(torch::Device(test::device_name()));
  m->eval();
  sharpen(m);
  torch::NoGradGuard ng;
  torch::manual_seed(4);
  WorldBatch b;
  b.tokens = torch::randint(0, kModelK, {2, 8, 60}, torch::kLong);
  b.actions = torch::randn({2, 8, 2});
  b = b.to(torch::Device(test::device_name()));
  auto x = m->embed(b);  // [2, 512, d]
  ASSERT_EQ(x.size(1), 512);
  auto body = m->make_cache(2, 512), pre = m->make_cache(2, 512);
  auto h0 = m->body(x.narrow(1, 0, 100), &body), h1 = m->body(x.narrow(1, 100, 412), &body);
  m->prefill(x.narrow(1, 0, 100), pre);
  m->prefill(x.narrow(1, 100, 412), pre);
  EXPECT_EQ(pre.length, 512);
  for (size_t l = 0; l < pre.k.size(); ++l) {
    EXPECT_LT((pre.k[l] - body.k[l]).abs().max().item<double>(), 1e-5) << "keys, layer " << l;
    EXPECT_LT((pre.v[l] - body.v[l]).abs().max().item<double>(), 1e-5) << "values, layer " << l;
  }
  auto full = m->body(x);  // no cache: one causal square
  // Blocks against one square sum attention in another order (and on other kernels by CPU): within n*u of the
  // 512 positions, layer on layer.
  const double tol = test::sum_tolerance(test::kFloat32Roundoff, 512, full.abs().max().item<double>(),
                                         c.world.n_layers);
  EXPECT_LT((torch::cat({h0, h1}, 1) - full).abs().max().item<double>(), tol);
  EXPECT_GT(full.std().item<double>(), 0.1);
}

// Sampling's fused per-token path against the general one (body, then logits), token by token on caches holding the
// same prefix: the same logits and the same cache contents, for one row and for guidance's two.
// The cached attention's own softmax (a vectorised exp, transformer.h) against LibTorch's, on row lengths around its
// eight-float blocks and on scores far apart (underflowing weights).
TEST(WorldModel, CachedAttentionSoftmaxMatchesLibTorchs) {
  torch::manual_seed(2);
  for (const int64_t n : {1, 7, 8, 9, 31, 1134}) {
    auto x = torch::randn({3, n}) * 6;
    if (n > 8) x[1][5] = -200.0f, x[2][0] = 60.0f;
    auto ours = x.clone();
    softmax_rows(ours.data_ptr<float>(), 3, n);
    auto want = torch::softmax(x.to(torch::kDouble), -1).to(torch::kFloat);
    EXPECT_LT((ours - want).abs().max().item<double>(), 1e-6) << n;
    EXPECT_LT(((ours - want).abs() / want.clamp_min(1e-30)).masked_select(want > 1e-30).max().item<double>(), 1e-5) << n;
    EXPECT_TRUE(torch::allclose(ours.sum(-1).to(torch::kDouble), torch::ones({3}, torch::kDouble), 0, 1e-6)) << n;
  }
}

// A bf16 cache (RolloutStepper under bf16 on the CPU) is read widened to float32: the cached attention over it gives
// what it gives over a float32 cache holding the same values (up to the order of float sums), and the new token's key and value are stored rounded
// to nearest even, as LibTorch rounds to bf16.
TEST(WorldModel, CachedAttentionOverABf16CacheIsTheFloatOneOverItsValues) {
  torch::manual_seed(4);
  const int64_t B = 2, H = 3, hd = 8, d = H * hd, cap = 40, offset = 29;
  auto K16 = torch::randn({B, H, hd, cap}).to(torch::kBFloat16), V16 = torch::randn({B, H, cap, hd}).to(torch::kBFloat16);
  auto K32 = K16.to(torch::kFloat), V32 = V16.to(torch::kFloat);
  auto qkv = torch::randn({B, 3 * d});
  auto k_new = qkv.narrow(1, d, d).to(torch::kBFloat16).to(torch::kFloat);
  auto v_new = qkv.narrow(1, 2 * d, d).to(torch::kBFloat16).to(torch::kFloat);
  auto y16 = attend_one_cached(qkv, K16, V16, offset, H);
  EXPECT_TRUE(torch::equal(K16.select(3, offset).reshape({B, d}).to(torch::kFloat), k_new));  // stored rounded
  EXPECT_TRUE(torch::equal(V16.select(2, offset).reshape({B, d}).to(torch::kFloat), v_new));
  auto rounded = qkv.clone();
  rounded.narrow(1, d, 2 * d).copy_(torch::cat({k_new, v_new}, 1));
  auto y32 = attend_one_cached(rounded, K32, V32, offset, H);
  EXPECT_TRUE(torch::allclose(y16, y32, 1e-6, 1e-6)) << (y16 - y32).abs().max().item<double>();  // sums' order aside
  EXPECT_GT(y16.abs().sum().item<double>(), 0);
}

TEST(WorldModel, TokenStepMatchesTheGeneralPath) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 5);
  if (!m->token_embedding->weight.device().is_cpu()) GTEST_SKIP() << "the fused token step is the CPU's";
  sharpen(m);
  torch::NoGradGuard ng;
  const TokenStep fast(*m);
  EXPECT_TRUE(TokenStep::applies(*m, 2));
  EXPECT_FALSE(TokenStep::applies(*m, 64));
  {
    Autocast bf16(Precision::kBf16, torch::kCPU);  // --precision bf16: the token step itself stays float32
    EXPECT_TRUE(TokenStep::applies(*m, 2));
  }
  for (int64_t B : {1, 2, 3, 4}) {
    auto b = random_batch(c, B, 2);
    auto x = m->embed(b);  // a prefix of two whole steps
    auto general = m->make_cache(B, m->layout.length()), fused = m->make_cache(B, m->layout.length());
    general.fused_single_token = false;
    m->body(x, &general);
    m->body(x, &fused);
    torch::manual_seed(6);
    double worst = 0, spread = 0, size = 0;  // the largest difference, relative to the largest logit
    for (int64_t i = 0; i < kModelN; ++i) {  // step t = 2's image tokens
      auto tok = torch::randint(0, kModelK, {B}, torch::kLong);
      auto want = m->logits(m->body(m->embed_image(tok.view({B, 1, 1}), 2, i).view({B, 1, m->d}), &general).select(1, 0));
      auto got = fast.logits(tok, 2, i, fused);
      ASSERT_EQ(got.sizes(), want.sizes());
      worst = std::max(worst, (got - want).abs().max().item<double>());
      size = std::max(size, want.abs().max().item<double>());
      spread = std::max(spread, want.std().item<double>());
    }
    EXPECT_LT(worst / size, 1e-5) << B << " rows, largest logit " << size;
    EXPECT_GT(spread, 0.1);
    EXPECT_EQ(fused.length, general.length);
    for (size_t l = 0; l < fused.k.size(); ++l) {
      auto n = fused.length;
      auto gk = general.k[l].narrow(3, 0, n), gv = general.v[l].narrow(2, 0, n);
      EXPECT_LT((fused.k[l].narrow(3, 0, n) - gk).abs().max().item<double>() / gk.abs().max().item<double>(), 1e-5);
      EXPECT_LT((fused.v[l].narrow(2, 0, n) - gv).abs().max().item<double>() / gv.abs().max().item<double>(), 1e-5);
    }
  }
  // Rows of a batch get exactly the numbers they get alone (each output sums its inputs in the same order).
  {
    auto b = random_batch(c, 4, 2);
    auto x = m->embed(b);
    auto batch = m->make_cache(4, m->layout.length());
    m->body(x, &batch);
    auto tok = torch::randint(0, kModelK, {4}, torch::kLong);
    std::vector<KVCache> alone(4);
    for (int64_t r = 0; r < 4; ++r) {  // the batch's own prefix, row r
      alone[size_t(r)] = batch;
      for (auto* layers : {&alone[size_t(r)].k, &alone[size_t(r)].v})
        for (auto& t : *layers) t = t.narrow(0, r, 1).clone();
    }
    for (int64_t i = 0; i < 3; ++i) {
      auto together = fast.logits(tok, 2, i, batch);
      for (int64_t r = 0; r < 4; ++r)
        EXPECT_TRUE(torch::equal(together[r], fast.logits(tok.narrow(0, r, 1), 2, i, alone[size_t(r)])[0]))
            << "row " << r << " token " << i;
    }
  }
  auto small = m->make_cache(1, 3);
  small.length = 3;
  EXPECT_THROW(fast.logits(torch::zeros({1}, torch::kLong), 0, 0, small), std::exception);  // full cache
  auto roomy = m->make_cache(1, 8);
  EXPECT_THROW(fast.logits(torch::full({1}, kModelK, torch::kLong), 0, 0, roomy), std::exception);  // id >= K
}

TEST(WorldModel, ParameterCountEqualsThePlan) {
  for (auto name : {"tiny.yaml", "default.yaml"}) {
    Config c = test::config(name);
    WorldModel m(c.world, c.image_tokens(), c.tokenizer.codebook_size);
    EXPECT_EQ(m->parameter_count(/*with_word_embedding=*/false), sizing::world_params(c).total) << name;
  }
}

// The plan's inference FLOPs against the built model: a token's multiply-adds are its blocks' matrices (read off
// the weights) and the head, plus attention's two products over the keys before it; the re-encoding of the
// one-step slide is every kept position through all blocks but the last, which only stores keys and values.
TEST(WorldModel, InferenceFlopsMatchThePlan) {
  for (auto name : {"tiny.yaml", "default.yaml"}) {
    Config c = test::config(name);
    WorldModel m(c.world, c.image_tokens(), c.tokenizer.codebook_size);
    double block = 0, kv = 0;  // multiply-adds of one block's matrices, and of its key and value projections
    for (const auto& p : (*m->blocks)[0]->named_parameters())
      if (p.value().dim() == 2) block += double(p.value().numel());
    kv = 2.0 / 3.0 * double((*m->blocks)[0]->named_parameters()["attn.qkv.weight"].numel());
    const auto& L = m->layout;
    const double layers = double(m->blocks->size()), d = double(m->d), head = double(m->head->weight.numel());
    double token = 0;
    for (int64_t i = 0; i < L.n; ++i) token += layers * (block + 2 * d * double((L.T - 1) * L.per_step() + L.m + i + 1)) + head;
    const auto f = sizing::inference_flops(c, 2);
    EXPECT_NEAR(f.world_token / (2 * token / double(L.n)), 1.0, 1e-9) << name;
    double reencode = 0;
    for (int64_t q = 0; q < (L.T - 1) * L.per_step(); ++q) reencode += (layers - 1) * (block + 2 * d * double(q + 1)) + kv;
    EXPECT_NEAR(f.world_frame_reencode / (2 * 2 * reencode), 1.0, 1e-9) << name;
    EXPECT_GT(f.world_frame_sampling, 2 * L.n * f.world_token) << name;  // the text and actions on top of the tokens
  }
}

// world.action_mlp: the plan counts its parameters, a new MLP starts where the linear layers were (fine-tuning a
// linear-action model changes nothing until it trains), and once trained the embedding is no longer affine in the
// action, which is what it is for.
TEST(WorldModel, ActionMlpStartsAtTheLinearEmbeddingAndBends) {
  Config c = test::config("tiny.yaml"), cm = test::config("tiny.yaml");
  cm.world.action_mlp = 8;
  WorldModel with(cm.world, cm.image_tokens(), cm.tokenizer.codebook_size);
  EXPECT_EQ(with->parameter_count(false), sizing::world_params(cm).total);
  EXPECT_GT(sizing::world_params(cm).total, sizing::world_params(c).total);

  auto lin = small_model(c, 3), mlp = small_model(cm, 4);
  train::init_from(*mlp, *lin, "linear", [](const std::string& k) { return k.find("_mlp.") != std::string::npos; });
  auto b = random_batch(c, 2, 3);
  b.actions.select(2, 1).copy_(torch::tensor({-2.0, -1.0, 0.0, 0.5, 1.0, 2.0}).view({2, 3}));  // normalised curvatures
  torch::NoGradGuard ng;
  EXPECT_TRUE(torch::allclose(lin->embed_actions(b), mlp->embed_actions(b), 0, 0));
  EXPECT_TRUE(torch::allclose(lin->forward(b), mlp->forward(b), 1e-6, 1e-6));
  // Any output weights: e(c) - e(0) is then not proportional to c. One step, five curvatures -2 .. 2.
  mlp->curvature_mlp[2]->as<torch::nn::Linear>()->weight.normal_(0.0, 0.5);
  auto b5 = random_batch(c, 5, 1);
  b5.actions.select(2, 1).copy_(torch::tensor({-2.0, -1.0, 0.0, 1.0, 2.0}).view({5, 1}));
  auto e = mlp->embed_actions(b5).select(1, 0).select(1, 1);  // [5, d] curvature tokens
  auto el = lin->embed_actions(b5).select(1, 0).select(1, 1);
  auto bend = [](const torch::Tensor& x, int i) {  // second difference at curvature i - 2
    return (x[i + 1] - 2 * x[i] + x[i - 1]).abs().max().item<double>();
  };
  EXPECT_GT(bend(e, 3), 1e-3);
  EXPECT_LT(bend(el, 3), 1e-5);  // the linear layer alone does not bend
  // Left and right are no longer one direction with opposite signs.
  EXPECT_GT((e[4] - e[2] + (e[0] - e[2])).abs().max().item<double>(), 1e-3);
  EXPECT_LT((el[4] - el[2] + (el[0] - el[2])).abs().max().item<double>(), 1e-5);
  Config bad = test::config("tiny.yaml");
  bad.world.action_mlp = -1;
  EXPECT_THROW(bad.validate(), std::exception);
}

// Distillation's KL term against LibTorch's own kl_div, only on the kept examples (their gradient alone is non-zero),
// 0 between equal logits and with nothing kept; wrong shapes are errors.
TEST(WorldModel, DistillationKlIsLibTorchsOnTheKeptExamplesOnly) {
  namespace F = torch::nn::functional;
  torch::manual_seed(4);
  auto s = torch::randn({3, 2, 4, 5}, torch::requires_grad()), t = torch::randn({3, 2, 4, 5});
  auto keep = torch::tensor({true, false, true});
  auto kl = world::image_token_kl(s, t, keep);
  auto idx = torch::tensor({0, 2});
  auto ref = F::kl_div(torch::log_softmax(s.index_select(0, idx), -1).reshape({-1, 5}),
                       torch::softmax(t.index_select(0, idx), -1).reshape({-1, 5}),
                       F::KLDivFuncOptions().reduction(torch::kSum)) / (2 * 2 * 4);
  EXPECT_NEAR(kl.item<double>(), ref.item<double>(), 1e-6);
  EXPECT_GT(kl.item<double>(), 0.01);
  kl.backward();
  EXPECT_EQ(s.grad()[1].abs().max().item<double>(), 0.0);
  EXPECT_GT(s.grad()[0].abs().max().item<double>(), 0.0);
  auto t2 = t.clone();
  t2[1] += 3;  // a dropped example's teacher does not matter
  EXPECT_NEAR(world::image_token_kl(s, t2, keep).item<double>(), kl.item<double>(), 1e-7);
  EXPECT_NEAR(world::image_token_kl(t, t, keep).item<double>(), 0.0, 1e-6);
  auto none = world::image_token_kl(s, t, torch::zeros({3}, torch::kBool));
  EXPECT_EQ(none.item<double>(), 0.0);
  none.backward();  // still a graph to step through
  EXPECT_THROW(world::image_token_kl(s, t.slice(0, 0, 2), keep), Error);
  EXPECT_THROW(world::image_token_kl(s, t, torch::ones({2}, torch::kBool)), Error);
}

TEST(WorldSampling, TopKNeverLeavesTheTopK) {
  torch::manual_seed(3);
  auto logits = torch::randn({4, 100});
  SamplingOptions o;
  o.strategy = Strategy::TopK;
  o.top_k = 5;
  auto gen = at::detail::createCPUGenerator(7);
  auto top = std::get<1>(logits.topk(5, -1));
  std::set<int64_t> seen;
  for (int r = 0; r < 300; ++r) {
    auto s = sample_tokens(logits, o, gen);
    for (int64_t b = 0; b < 4; ++b) {
      int64_t v = s[b].item<int64_t>();
      EXPECT_TRUE((top[b] == v).any().item<bool>());
      if (b == 0) seen.insert(v);
    }
  }
  EXPECT_EQ(seen.size(), 5u);  // and it does sample, not just take the argmax
  // Top-k draws follow the renormalised distribution (the sampler draws among the k kept logits only).
  {
    auto row = torch::full({1, 100}, -4.0f);
    for (int64_t j = 0; j < 6; ++j) row[0][10 * j + 3] = 1.0f - 0.5f * float(j);  // six leaders, the 6th cut
    SamplingOptions hot = o;
    hot.temperature = 0.7;
    auto want = sampling_distribution(row, hot)[0];
    std::vector<int> count(100, 0);
    const int draws = 6000;
    for (int r = 0; r < draws; ++r) ++count[size_t(sample_tokens(row, hot, gen)[0].item<int64_t>())];
    for (int64_t j = 0; j < 100; ++j)
      EXPECT_NEAR(count[size_t(j)] / double(draws), want[j].item<double>(), 0.025) << "token " << j;
  }
  // Argmax, top-p and temperature.
  o.strategy = Strategy::Argmax;
  EXPECT_TRUE(torch::equal(sample_tokens(logits, o, gen), logits.argmax(-1)));
  o.strategy = Strategy::TopP;
  o.top_p = 0.5;
  auto p = sampling_distribution(logits, o);
  auto full = torch::softmax(logits, -1);
  for (int64_t b = 0; b < 4; ++b) {
    auto kept = p[b] > 0;
    double mass = full[b].masked_select(kept).sum().item<double>();
    EXPECT_GE(mass, 0.5);
    // Dropping the least likely kept token would fall below top_p: the nucleus is minimal.
    double smallest = full[b].masked_select(kept).min().item<double>();
    EXPECT_LT(mass - smallest, 0.5);
  }
  o.strategy = Strategy::Sample;
  o.temperature = 0.5;
  EXPECT_TRUE(torch::allclose(sampling_distribution(logits, o), torch::softmax(logits / 0.5, -1), 1e-5, 1e-6));
  EXPECT_NE(test::error_of([] { parse_strategy("greedy"); }).find("greedy"), std::string::npos);
}

TEST(WorldGuidance, FormulaAndSchedules) {
  auto c = torch::tensor({1.0, 2.0}), u = torch::tensor({0.5, 3.0});
  EXPECT_TRUE(torch::allclose(guide(c, u, 2.0), torch::tensor({3.0 * 1.0 - 2.0 * 0.5, 3.0 * 2.0 - 2.0 * 3.0})));
  GuidanceSchedule g;
  g.scale = 4;
  EXPECT_DOUBLE_EQ(g.at(3, 7, 10), 4);
  g.tokens = GuidanceSchedule::Tokens::Linear;
  EXPECT_DOUBLE_EQ(g.at(0, 0, 10), 4);
  EXPECT_DOUBLE_EQ(g.at(0, 9, 10), 0);
  EXPECT_NEAR(g.at(0, 3, 10), 4 * (1 - 3.0 / 9), 1e-12);
  g.tokens = GuidanceSchedule::Tokens::Constant;
  g.frames = GuidanceSchedule::Frames::Cosine;
  g.plateau = 2;
  g.total_frames = 8;
  EXPECT_DOUBLE_EQ(g.at(0, 0, 10), 4);
  EXPECT_DOUBLE_EQ(g.at(2, 0, 10), 4);
  EXPECT_NEAR(g.at(7, 0, 10), 0, 1e-12);
  for (int f = 2; f < 7; ++f) EXPECT_GT(g.at(f, 0, 10), g.at(f + 1, 0, 10));
  EXPECT_NEAR(g.at(4, 0, 10), 4 * 0.5 * (1 + std::cos(M_PI * 2 / 5.0)), 1e-12);  // u = (4 - 2) / (8 - 2 - 1)
}

TEST(WorldSampling, KeepTopKRanksByAnotherTensor) {
  auto cond = torch::tensor({{0.0, 3.0, 1.0, 2.0}, {5.0, 4.0, -1.0, 0.0}});
  auto guided = torch::tensor({{9.0, -1.0, 7.0, 0.5}, {1.0, 2.0, 30.0, 3.0}});
  auto w = keep_top_k(guided, cond, 2);
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_TRUE(torch::equal(w, torch::tensor({{-inf, -1.0f, -inf, 0.5f}, {1.0f, 2.0f, -inf, -inf}})));
  EXPECT_TRUE(torch::equal(w.argmax(-1), torch::tensor({3, 1})));  // not the guided favourites 0 and 2
  EXPECT_TRUE(torch::equal(keep_top_k(guided, cond, 4), guided));
  EXPECT_TRUE(torch::equal(keep_top_k(cond, cond, 1).argmax(-1), cond.argmax(-1)));
  EXPECT_NE(test::error_of([&] { keep_top_k(guided, cond, 0); }).find("top_k must be >= 1"), std::string::npos);
}

// Every generated frame must be the argmax of a full forward over the window the sampler saw: the last T steps
// (or all steps before the window fills). This checks the KV cache and the sliding window's re-indexed positions.
TEST(WorldRollout, ArgmaxRolloutIsConsistentAcrossTheSlidingWindow) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 5);
  const int64_t T = c.world.context_steps, P = 2, F = T + 3;
  RolloutPrompt p;
  torch::manual_seed(9);
  p.tokens = torch::randint(0, kModelK, {P, kModelN}, torch::kLong);
  p.actions = torch::randn({P + F, 2});
  p.text_ids = torch::randint(0, c.world.text_vocab, {P + F, c.world.text_tokens}, torch::kLong);
  const int threads = at::get_num_threads();
  for (int one_thread : {0, 1})  // one intra-op thread: the next window is encoded ahead on a second thread
  for (auto [bias, run] : std::vector<std::pair<double, double>>{{0.0, 0.0}, {1.5, 0.0}, {1.5, 3.0}})
  for (int stride : {1, 2, int(T) - 1}) {
  at::set_num_threads(one_thread ? 1 : threads);
  m->cfg.copy_bias = bias;  // the rollout adds the copy bias exactly where forward() does
  m->cfg.copy_bias_run = run;
  RolloutOptions o;
  o.frames = int(F);
  o.sampling.strategy = Strategy::Argmax;
  o.window_stride = stride;
  auto r = rollout(m, p, o);
  ASSERT_EQ(r.tokens.sizes(), (std::vector<int64_t>{1, P + F, kModelN}));
  EXPECT_TRUE(torch::equal(r.tokens[0].narrow(0, 0, P), p.tokens));
  torch::NoGradGuard ng;
  int64_t k0 = 0;  // first step of the window frame k sees: it drops `stride` steps when T are in it
  for (int64_t k = 0; k < P + F; ++k) {
    if (k - k0 == T) k0 = k - (T - stride);
    if (k < P) continue;
    WorldBatch b;
    b.tokens = r.tokens.narrow(1, k0, k - k0 + 1);
    b.actions = p.actions.narrow(0, k0, k - k0 + 1).unsqueeze(0);
    b.text_ids = p.text_ids.narrow(0, k0, k - k0 + 1).unsqueeze(0);
    auto want = m->forward(b).select(1, k - k0).argmax(-1);  // [1, n]
    EXPECT_TRUE(torch::equal(want[0], r.tokens[0][k]))
        << "frame " << k << ", stride " << stride << ", bias " << bias << " + " << run << ", one thread " << one_thread;
  }
  }
  at::set_num_threads(threads);
  m->cfg.copy_bias = m->cfg.copy_bias_run = 0;
  RolloutOptions bad;
  bad.window_stride = int(T);
  EXPECT_NE(test::error_of([&] { rollout(m, p, bad); }).find("window stride"), std::string::npos);
}

// The lookahead (the next window's history encoded on a second thread) gives the plain path's tokens, and a copy
// made while it runs (a fork) continues exactly as the original: top-k draws, past the window several times.
TEST(WorldRollout, LookaheadAndForksMidFrameGiveTheSameTokens) {
  Config c = test::config("tiny.yaml");
  const int64_t n = 100;  // the newest step goes to the second thread in three chunks
  torch::manual_seed(5);
  WorldModel m(c.world, n, kModelK);
  m->eval();
  sharpen(m, 3.0);
  const int64_t T = c.world.context_steps, P = 2, F = 3 * T;
  RolloutPrompt p;
  torch::manual_seed(9);
  p.tokens = torch::randint(0, kModelK, {P, n}, torch::kLong);
  p.actions = torch::randn({P + F, 2});
  const int threads = at::get_num_threads();
  at::set_num_threads(1);
  Precision precision = Precision::kFp32;
  auto run = [&](bool lookahead, int fork_at) {
    RolloutOptions o;
    o.seed = 4;
    o.lookahead = lookahead;
    o.precision = precision;
    RolloutStepper s(m, o, 1);
    std::optional<RolloutStepper> copy;
    for (int64_t k = 0; k < P; ++k) s.step(p, p.tokens[k]);
    for (int64_t k = P; k < P + F; ++k) {
      s.step(p);
      if (k == fork_at) copy.emplace(s.fork());  // the lookahead job for the next step is in flight or just done
    }
    if (fork_at < 0) return s.tokens();
    for (int64_t k = fork_at + 1; k < P + F; ++k) copy->step(p);
    EXPECT_TRUE(torch::equal(copy->tokens(), s.tokens())) << "fork after step " << fork_at;
    return copy->tokens();
  };
  auto plain = run(false, -1), ahead = run(true, -1);
  EXPECT_TRUE(torch::equal(plain, ahead));
  run(true, int(T + 2));
  {  // and at bf16, whose cache is bf16 (RolloutStepper::new_cache), where this CPU does bf16 (else fp32 again)
    SCOPED_TRACE("bf16");
    precision = precision_for("bf16", torch::kCPU);
    EXPECT_TRUE(torch::equal(run(false, -1), run(true, -1)));
    run(true, int(T + 2));
    precision = Precision::kFp32;
  }
  at::set_num_threads(threads);
  EXPECT_GT(std::get<0>(at::_unique(ahead.narrow(1, P, F))).numel(), 4);  // it samples, it does not repeat one code
}

// The raw per-token choice (token_choice.h, with the fused step) and the LibTorch one (copy bias, guide, keep_top_k,
// sample_tokens, with the general path) choose the same tokens: argmax, top-k, guided within the conditional top k,
// text-guided over all codes, and the copy bias on the previous frame's code (one for every slot, and more in runs).
TEST(WorldRollout, RawTokenChoiceGivesTheLibTorchPathsTokens) {
  Config c = test::config("tiny.yaml");
  const int64_t n = 12, K = 64;
  torch::manual_seed(5);
  WorldModel m(c.world, n, K);
  m->eval();
  sharpen(m, 2.0);
  const int64_t T = c.world.context_steps, P = 2, F = T + 2;
  RolloutPrompt p;
  torch::manual_seed(9);
  p.tokens = torch::randint(0, K, {P, n}, torch::kLong);
  p.actions = torch::randn({P + F, 2});
  const int threads = at::get_num_threads();
  at::set_num_threads(1);
  for (const int setting : {0, 1, 2, 3, 4, 5}) {
    SCOPED_TRACE("setting " + std::to_string(setting));
    RolloutOptions o;
    o.frames = int(F);
    o.seed = 4;
    o.sampling.top_k = 10;
    o.sampling.temperature = 0.8;
    RolloutPrompt q = p;
    if (setting == 0) o.sampling.strategy = Strategy::Argmax;
    if (setting >= 2) o.guidance.scale = 3;  // 2: actions, within the conditional top k
    if (setting == 3) q.text_ids = torch::randint(0, c.world.text_vocab, {P + F, c.world.text_tokens}, torch::kLong);
    if (setting >= 4) m->cfg.copy_bias = 1.5;
    if (setting == 5) m->cfg.copy_bias_run = 2.5;
    o.fused_tokens = false;
    auto general = rollout(m, q, o).tokens;
    o.fused_tokens = true;
    auto raw = rollout(m, q, o).tokens;
    m->cfg.copy_bias = m->cfg.copy_bias_run = 0;
    EXPECT_TRUE(torch::equal(general, raw));
    if (setting > 0) {
      EXPECT_GT(std::get<0>(at::_unique(raw.narrow(1, P, F))).numel(), 8);  // it does sample
    }
  }
  at::set_num_threads(threads);
}

TEST(WorldRollout, GuidanceUsesOneBatchAndNegativePromptReplacesUnconditional) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 6);
  const int64_t F = 3;
  RolloutPrompt p;
  torch::manual_seed(2);
  p.text_ids = torch::randint(2, c.world.text_vocab, {F, c.world.text_tokens}, torch::kLong);
  RolloutOptions o;
  o.frames = int(F);
  o.futures = 2;
  o.sampling.strategy = Strategy::Argmax;
  auto plain = rollout(m, p, o);
  // A negative prompt equal to the prompt: l_cond == l_uncond, so any guidance scale gives the same tokens.
  auto q = p;
  q.negative_text_ids = p.text_ids;
  o.guidance.scale = 5;
  auto same = rollout(m, q, o);
  EXPECT_TRUE(torch::equal(plain.tokens, same.tokens));
  // Real guidance against the null text changes the argmax path.
  auto guided = rollout(m, p, o);
  EXPECT_FALSE(torch::equal(plain.tokens, guided.tokens));
  // Futures differ under sampling, and a seed reproduces them.
  o.guidance.scale = 0;
  o.sampling.strategy = Strategy::Sample;
  o.seed = 4;
  auto s1 = rollout(m, p, o), s2 = rollout(m, p, o);
  EXPECT_TRUE(torch::equal(s1.tokens, s2.tokens));
  EXPECT_FALSE(torch::equal(s1.tokens[0], s1.tokens[1]));
}

namespace {

// A random prompt of P frames with random actions (x `scale`) for all P + F steps, drawn from `seed`.
RolloutPrompt action_prompt(int64_t P, int64_t F, uint64_t seed, double scale) {
  torch::manual_seed(seed);
  RolloutPrompt p;
  p.tokens = torch::randint(0, kModelK, {P, kModelN}, torch::kLong);
  p.actions = torch::randn({P + F, 2}) * scale;
  return p;
}

}  // namespace

// Guidance on the actions alone (no text; `gaia eval --action-guidance`): the unconditional rows see null action
// tokens, so the guided frame is the argmax of eq. 2 over two plain forward passes, with and without the actions.
TEST(WorldRollout, ActionGuidanceContrastsWithNullActions) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 6);
  const int64_t P = 2, F = 1;
  const double s = 2;
  RolloutPrompt p = action_prompt(P, F, 5, 3);
  RolloutOptions o;
  o.frames = int(F);
  o.sampling.strategy = Strategy::Argmax;
  o.guidance.scale = s;
  auto r = rollout(m, p, o);
  torch::NoGradGuard ng;
  WorldBatch b;
  b.tokens = r.tokens.repeat({2, 1, 1});  // [2, P + F, n]
  b.actions = p.actions.unsqueeze(0).repeat({2, 1, 1});
  b.use_action = torch::tensor({true, false});
  auto l = m->forward(b).select(1, P);  // [2, n, K]: teacher-forced on the rollout's own tokens
  EXPECT_FALSE(torch::allclose(l[0], l[1]));  // the two branches differ: the check below is not vacuous
  EXPECT_TRUE(torch::equal(guide(l[0], l[1], s).argmax(-1), r.tokens[0][P]));
}

// Negative actions (`gaia eval --action-negative mirror`): the unconditional rows see them instead of null actions,
// so the guided frame is eq. 2's argmax between the command and its mirror image.
TEST(WorldRollout, NegativeActionsReplaceTheNullOnes) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 6);
  const int64_t P = 2, F = 1;
  RolloutPrompt p = action_prompt(P, F, 7, 10);
  p.negative_actions = counter_actions(p.actions, 0);
  EXPECT_TRUE(torch::equal(p.negative_actions.select(1, 0), p.actions.select(1, 0)));  // speed kept
  EXPECT_TRUE(torch::equal(p.negative_actions.select(1, 1), -p.actions.select(1, 1)));
  auto later = counter_actions(p.actions.unsqueeze(0).repeat({2, 1, 1}), P);  // per future, from the first generated step
  EXPECT_TRUE(torch::equal(later.narrow(1, 0, P), p.actions.narrow(0, 0, P).unsqueeze(0).repeat({2, 1, 1})));
  EXPECT_TRUE(torch::equal(later.select(1, P).select(1, 1), -p.actions[P][1].repeat({2})));
  EXPECT_NE(test::error_of([&] { counter_actions(torch::zeros({3, 3}), 0); }).find("counter_actions"), std::string::npos);
  RolloutOptions o;
  o.frames = int(F);
  o.sampling.strategy = Strategy::Argmax;
  o.guidance.scale = 40;
  auto r = rollout(m, p, o);
  torch::NoGradGuard ng;
  WorldBatch b;
  b.tokens = r.tokens.repeat({3, 1, 1});
  b.actions = torch::stack({p.actions, p.negative_actions, p.actions});
  b.use_action = torch::tensor({true, true, false});
  auto l = m->forward(b).select(1, P);  // [3, n, K]: command, mirrored command, no actions
  EXPECT_FALSE(torch::equal(guide(l[0], l[1], 40).argmax(-1), guide(l[0], l[2], 40).argmax(-1)));  // not vacuous
  EXPECT_TRUE(torch::equal(guide(l[0], l[1], 40).argmax(-1), r.tokens[0][P]));
  p.actions = torch::Tensor();
  EXPECT_NE(test::error_of([&] { rollout(m, p, o); }).find("negative actions need actions"), std::string::npos);
}

// Action guidance within the conditional top k (SamplingOptions::guide_actions_within_top_k): with k = 1 the only
// candidate is the conditional argmax, whatever the guided logits say; unconstrained, or when the guidance contrasts
// text too, top-1 of the guided logits is eq. 2's argmax.
TEST(WorldRollout, ActionGuidanceStaysWithinTheConditionalTopK) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 6);
  const int64_t P = 2, F = 1;
  RolloutPrompt p = action_prompt(P, F, 5, 3);
  const auto text = torch::randint(2, c.world.text_vocab, {P + F, c.world.text_tokens}, torch::kLong);
  RolloutOptions o;
  o.frames = int(F);
  o.sampling.strategy = Strategy::TopK;
  o.sampling.top_k = 1;
  o.guidance.scale = 8;
  for (int mode = 0; mode < 3; ++mode) {  // 0: actions, constrained; 1: actions, unconstrained; 2: text, "constrained"
    o.sampling.guide_actions_within_top_k = mode != 1;
    if (mode == 2) p.text_ids = text;
    auto r = rollout(m, p, o);
    torch::NoGradGuard ng;
    WorldBatch b;
    b.tokens = r.tokens.repeat({2, 1, 1});
    b.actions = p.actions.unsqueeze(0).repeat({2, 1, 1});
    b.use_action = torch::tensor({true, false});
    if (mode == 2) {
      b.text_ids = text.unsqueeze(0).repeat({2, 1, 1});
      b.use_text = torch::tensor({true, false});
    }
    auto l = m->forward(b).select(1, P);  // [2, n, K] teacher-forced on the rollout's own tokens
    auto cond_pick = l[0].argmax(-1), guided_pick = guide(l[0], l[1], o.guidance.scale).argmax(-1);
    EXPECT_FALSE(torch::equal(cond_pick, guided_pick));  // guidance would change the frame: the test can fail
    EXPECT_TRUE(torch::equal(mode == 0 ? cond_pick : guided_pick, r.tokens[0][P])) << "mode " << mode;
  }
}

// One batched rollout with a prompt, actions and text per future gives what separate rollouts give (argmax), with
// and without guidance, including across the sliding window: evaluation runs many prompts x commands this way.
TEST(WorldRollout, PerFuturePromptsMatchSeparateRollouts) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 8);
  const int64_t N = 3, P = 2, F = c.world.context_steps, m_txt = c.world.text_tokens;
  torch::manual_seed(11);
  RolloutPrompt batched;
  batched.tokens = torch::randint(0, kModelK, {N, P, kModelN}, torch::kLong);
  batched.actions = torch::randn({N, P + F, 2});
  batched.text_ids = torch::randint(2, c.world.text_vocab, {N, P + F, m_txt}, torch::kLong);
  for (double scale : {0.0, 2.0}) {
    RolloutOptions o;
    o.frames = int(F);
    o.futures = int(N);
    o.sampling.strategy = Strategy::Argmax;
    o.guidance.scale = scale;
    auto all = rollout(m, batched, o);
    ASSERT_EQ(all.tokens.sizes(), (std::vector<int64_t>{N, P + F, kModelN}));
    o.futures = 1;
    for (int64_t i = 0; i < N; ++i) {
      RolloutPrompt one;
      one.tokens = batched.tokens[i];
      one.actions = batched.actions[i];
      one.text_ids = batched.text_ids[i];
      auto r = rollout(m, one, o);
      EXPECT_TRUE(torch::equal(r.tokens[0], all.tokens[i])) << "future " << i << ", guidance " << scale;
    }
  }
  RolloutPrompt bad = batched;
  bad.actions = torch::zeros({N + 1, P + F, 2});
  RolloutOptions o;
  o.frames = int(F);
  o.futures = int(N);
  EXPECT_NE(test::error_of([&] { rollout(m, bad, o); }).find("futures = 3"), std::string::npos);
}

TEST(WorldRollout, BadPromptsAreClearErrors) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c);
  RolloutOptions o;
  o.frames = 2;
  RolloutPrompt p;
  p.tokens = torch::zeros({c.world.context_steps + 1, kModelN}, torch::kLong);
  EXPECT_NE(test::error_of([&] { rollout(m, p, o); }).find("context"), std::string::npos);
  p.tokens = torch::full({1, kModelN}, kModelK, torch::kLong);
  EXPECT_NE(test::error_of([&] { rollout(m, p, o); }).find("K = 32"), std::string::npos);
  p.tokens = torch::zeros({1, kModelN}, torch::kLong);
  p.actions = torch::zeros({2, 2});  // needs 1 + 2 rows
  EXPECT_NE(test::error_of([&] { rollout(m, p, o); }).find("actions has 2 rows"), std::string::npos);
}

TEST(WorldModel, ActivationCheckpointingGivesTheSameGradients) {
  Config c = test::config("tiny.yaml");
  auto grads = [&](bool ckpt) {
    Config cc = c;
    cc.world.activation_checkpointing = ckpt;
    auto m = small_model(cc, 11);
    m->train();
    auto b = random_batch(cc, 2, 3);
    auto loss = image_token_loss(m->forward(b), b.tokens);
    loss.backward();
    std::vector<torch::Tensor> g;  // blocks.0.attn.qkv.weight first: a parameter only the checkpointed path reaches
    g.push_back(m->named_parameters()["blocks.0.attn.qkv.weight"].grad().clone());
    for (auto& p : m->parameters()) g.push_back(p.grad().defined() ? p.grad().clone() : torch::zeros_like(p));
    return std::make_pair(loss.item<double>(), g);
  };
  auto [l0, g0] = grads(false);
  auto [l1, g1] = grads(true);
  EXPECT_NEAR(l0, l1, 1e-6);
  ASSERT_EQ(g0.size(), g1.size());
  double worst = 0;
  for (size_t i = 0; i < g0.size(); ++i) worst = std::max(worst, (g0[i] - g1[i]).abs().max().item<double>());
  EXPECT_LT(worst, 1e-5);
  EXPECT_GT(g1[0].abs().sum().item<double>(), 0);
}

// world.copy_bias adds exactly b to the logit of the code each position held one frame earlier, and nothing else;
// the first frame of the window has no earlier frame in view. A large bias makes a sampled rollout repeat the prompt.
TEST(WorldModel, CopyBiasRaisesOnlyThePreviousFramesCode) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 2);
  torch::NoGradGuard ng;
  auto b = random_batch(c, 2, 3);
  auto base = m->forward(b);
  m->cfg.copy_bias = 0.75;
  auto biased = m->forward(b);
  auto want = torch::zeros_like(base);
  for (int64_t x = 0; x < 2; ++x)
    for (int64_t t = 1; t < 3; ++t)
      for (int64_t i = 0; i < kModelN; ++i) want[x][t][i][b.tokens[x][t - 1][i].item<int64_t>()] = 0.75;
  EXPECT_TRUE(torch::allclose(biased - base, want, 0, 1e-5));

  m->cfg.copy_bias = 100;
  RolloutPrompt p;
  p.tokens = torch::randint(0, kModelK, {2, kModelN}, torch::kLong);
  RolloutOptions o;
  o.frames = 3;
  o.futures = 2;
  o.seed = 7;
  auto r = rollout(m, p, o);  // top-k sampling
  for (int64_t k = 2; k < 5; ++k) EXPECT_TRUE(torch::equal(r.tokens[0][k], p.tokens[1])) << k;
  m->cfg.copy_bias = 0;
  auto free = rollout(m, p, o);
  EXPECT_FALSE(torch::equal(free.tokens[0][2], p.tokens[1]));
}

// world.copy_bias_run adds its logit on top where the slot before (i - 1, the same frame) kept its code, never at
// slot 0, and the rollout's bias per slot is forward()'s (CopyBias::at against per_slot).
TEST(WorldModel, CopyBiasRunAddsWhereTheSlotBeforeKeptItsCode) {
  Config c = test::config("tiny.yaml");
  auto m = small_model(c, 2);
  torch::NoGradGuard ng;
  auto b = random_batch(c, 2, 3);
  b.tokens[0][1].narrow(0, 0, kModelN / 2).copy_(b.tokens[0][0].narrow(0, 0, kModelN / 2));  // a run of kept codes
  b.tokens[1][2].copy_(b.tokens[1][1]);                                                        // a whole frame kept
  auto base = m->forward(b);
  m->cfg.copy_bias = 0.75;
  m->cfg.copy_bias_run = 0.5;
  auto biased = m->forward(b);
  m->cfg.copy_bias = m->cfg.copy_bias_run = 0;
  auto want = torch::zeros_like(base);
  int64_t runs = 0;
  const CopyBias copy{0.75, 0.5};
  for (int64_t x = 0; x < 2; ++x)
    for (int64_t t = 1; t < 3; ++t)
      for (int64_t i = 0; i < kModelN; ++i) {
        const bool run = i > 0 && b.tokens[x][t][i - 1].item<int64_t>() == b.tokens[x][t - 1][i - 1].item<int64_t>();
        runs += run;
        want[x][t][i][b.tokens[x][t - 1][i].item<int64_t>()] = copy.at(run);
      }
  EXPECT_GE(runs, kModelN / 2 - 1 + kModelN - 1);
  EXPECT_TRUE(torch::allclose(biased - base, want, 0, 1e-5));
  EXPECT_DOUBLE_EQ(copy.at(true), 1.25);
  EXPECT_DOUBLE_EQ(copy.at(false), 0.75);
}

// The fit: with outcomes drawn from p0 raised by a known bias, the maximum-likelihood bias is found again, and at the
// optimum the expected number of copies equals the observed one. Degenerate outcomes are an error.
TEST(WorldCalibration, FitRecoversAKnownCopyBias) {
  torch::manual_seed(3);
  const int64_t N = 200000;
  auto p0 = torch::rand({N}, torch::kDouble) * 0.45 + 0.05;
  const double b = 0.7;
  auto pb = p0 * std::exp(b) / (1 - p0 + p0 * std::exp(b));
  auto y = (torch::rand({N}, torch::kDouble) < pb).to(torch::kDouble);
  const double fit = fit_copy_bias(p0.log(), y);
  EXPECT_NEAR(fit, b, 0.03);
  auto pf = p0 * std::exp(fit) / (1 - p0 + p0 * std::exp(fit));
  EXPECT_NEAR(pf.sum().item<double>(), y.sum().item<double>(), 1e-3);
  EXPECT_NEAR(fit_copy_bias(p0.log(), (torch::rand({N}, torch::kDouble) < p0).to(torch::kDouble)), 0.0, 0.03);
  EXPECT_NE(test::error_of([&] { fit_copy_bias(p0.log(), torch::zeros({N})); }).find("no finite optimum"),
            std::string::npos);
  EXPECT_NE(test::error_of([&] { fit_copy_bias(p0.log(), torch::zeros({3})); }).find("as many"), std::string::npos);
}

// Slots after a kept code copied with a larger bias than the others: both are found again; where the slots of one
// kind never copy, one bias is fitted for all.
TEST(WorldCalibration, FitFindsTheRunsOwnBias) {
  torch::manual_seed(4);
  const int64_t N = 200000;
  auto p0 = torch::rand({N}, torch::kDouble) * 0.45 + 0.05;
  auto run = torch::rand({N}) < 0.3;
  const double b = 0.4, r = 1.6;
  auto bias = torch::where(run, torch::full({N}, b + r, torch::kDouble), torch::full({N}, b, torch::kDouble));
  auto pb = p0 * bias.exp() / (1 - p0 + p0 * bias.exp());
  auto y = (torch::rand({N}, torch::kDouble) < pb).to(torch::kDouble);
  const CopyBias fit = fit_copy_biases(p0.log(), y, run);
  EXPECT_NEAR(fit.bias, b, 0.04);
  EXPECT_NEAR(fit.run, r, 0.08);
  const CopyBias one = fit_copy_biases(p0.log(), y * (~run).to(torch::kDouble), run);
  EXPECT_EQ(one.run, 0.0);
  EXPECT_NEAR(one.bias, fit_copy_bias(p0.log(), y * (~run).to(torch::kDouble)), 1e-9);
}
