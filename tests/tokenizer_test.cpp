// Image tokenizer: quantiser behaviour, shapes per config, parameter counts = gaia plan, overfit, errors.
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/core/error.h"
#include "gaia/sizing/sizing.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/tokenizer/discriminator.h"
#include "test_util.h"

using namespace gaia;
using namespace gaia::tokenizer;

namespace {
}  // namespace

TEST(Quantizer, PicksNearestCodeAndPassesGradientsStraightThrough) {
  torch::manual_seed(0);
  VectorQuantizer q(8, 4, 16);
  auto z = torch::randn({2, 8, 3, 5}, torch::requires_grad());
  auto out = q->forward(z);
  EXPECT_EQ(out.indices.sizes(), (std::vector<int64_t>{2, 3, 5}));
  EXPECT_EQ(out.z_q.sizes(), z.sizes());
  // Nearest by brute force: the chosen code has the smallest L2 distance among normalised codes.
  auto ze = torch::nn::functional::normalize(q->proj_in(z.permute({0, 2, 3, 1}).reshape({-1, 8})),
                                             torch::nn::functional::NormalizeFuncOptions().dim(1));
  auto cb = q->normalized_codebook();
  auto d = torch::cdist(ze, cb);
  EXPECT_TRUE(torch::equal(d.argmin(1), out.indices.reshape({-1})));
  // Straight-through: the gradient reaches the encoder input.
  out.z_q.sum().backward();
  ASSERT_TRUE(z.grad().defined());
  EXPECT_GT(z.grad().abs().sum().item<double>(), 0);
  // Losses: equal values, different gradients (codebook loss moves codes only, commitment the encoder only).
  EXPECT_NEAR(out.codebook_loss.item<double>(), out.commit_loss.item<double>(), 1e-6);
  q->zero_grad();
  auto out2 = q->forward(z.detach());
  out2.codebook_loss.backward();
  EXPECT_GT(q->codebook->weight.grad().abs().sum().item<double>(), 0);
  EXPECT_FALSE(q->proj_in->weight.grad().defined() && q->proj_in->weight.grad().abs().sum().item<double>() > 0);
  // lookup(indices) reproduces the quantised features.
  EXPECT_TRUE(torch::allclose(q->lookup(out.indices), out.z_q, 1e-5, 1e-5));
}

TEST(Quantizer, DeadCodeRestartReplacesUnusedCodes) {
  torch::manual_seed(0);
  VectorQuantizer q(8, 4, 16);
  auto usage = torch::zeros({16});
  usage.index_put_({torch::indexing::Slice(0, 4)}, 3);
  auto before = q->codebook->weight.clone();
  auto gen = at::detail::createCPUGenerator(1);
  EXPECT_EQ(q->restart_dead_codes(usage, torch::randn({10, 4}), gen), 12);
  EXPECT_TRUE(torch::equal(before.slice(0, 0, 4), q->codebook->weight.slice(0, 0, 4)));
  EXPECT_FALSE(torch::equal(before.slice(0, 4), q->codebook->weight.slice(0, 4)));
}

TEST(Tokenizer, ShapesAndParameterCountsMatchPlanForEveryConfig) {
  for (auto name : {"tiny.yaml", "default.yaml"}) {
    Config c = test::config(name);
    ImageTokenizer t(c);
    EXPECT_EQ(t->parameter_count(), sizing::tokenizer_params(c).total) << name;
    PatchDiscriminator d(c.tokenizer);
    int64_t nd = 0;
    for (auto& p : d->parameters()) nd += p.numel();
    EXPECT_EQ(nd, sizing::discriminator_params(c)) << name;
    torch::NoGradGuard ng;
    auto x = torch::rand({2, 3, c.data.height, c.data.width}) * 2 - 1;
    auto o = t->forward(x);
    EXPECT_EQ(o.reconstruction.sizes(), x.sizes());
    EXPECT_EQ(o.q.indices.sizes(), (std::vector<int64_t>{2, c.tokens_h(), c.tokens_w()}));
    EXPECT_GE(o.q.indices.min().item<int64_t>(), 0);
    EXPECT_LT(o.q.indices.max().item<int64_t>(), c.tokenizer.codebook_size);
    EXPECT_EQ(d->forward(x).size(1), 1);
  }
  // Paper scale is too big to build in a test; its count comes from the same formula (gaia plan).
}

TEST(Tokenizer, WrongResolutionIsAClearError) {
  Config c = test::config("tiny.yaml");
  ImageTokenizer t(c);
  try {
    t->encode(torch::zeros({1, 3, 48, 64}));
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("[B, 3, 32, 64]"), std::string::npos) << e.what();
  }
}

// Teacher cross-checks against torchvision (tools/make_teacher_fixtures.py): relative error <= 1e-4.
#include "gaia/core/safetensors.h"
#include "gaia/tokenizer/teachers.h"
#include "gaia/torch/tensor_io.h"

namespace {
torch::Tensor fixture(const std::string& file, const std::string& name) {
  SafetensorsFile f(test::source_dir() / "tests" / "fixtures" / file);
  return tensor_from_view(f.get(name));
}
}  // namespace

TEST(Teachers, Vgg16MatchesTorchvision) {
  Vgg16 vgg(test::source_dir() / "tests" / "fixtures" / "vgg16_narrow.safetensors");
  torch::NoGradGuard ng;
  auto taps = vgg->forward(fixture("vgg16_narrow_io.safetensors", "input"));
  ASSERT_EQ(taps.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    auto want = fixture("vgg16_narrow_io.safetensors", "relu" + std::to_string(i));
    ASSERT_EQ(taps[static_cast<size_t>(i)].sizes(), want.sizes()) << i;
    EXPECT_LE(test::rel_err(taps[static_cast<size_t>(i)], want), 1e-4) << "relu tap " << i;
  }
}

TEST(Teachers, DinoViTMatchesTorchvisionInBothLayouts) {
  auto x = fixture("vit_io.safetensors", "input");
  auto want = fixture("vit_io.safetensors", "patches");
  for (auto file : {"vit_tv.safetensors", "vit_timm.safetensors"}) {
    DinoViT vit(test::source_dir() / "tests" / "fixtures" / file);
    EXPECT_EQ(vit->heads, 2);
    EXPECT_EQ(vit->patch, 8);
    torch::NoGradGuard ng;
    auto got = vit->forward(x);
    ASSERT_EQ(got.sizes(), want.sizes()) << file;
    EXPECT_LE(test::rel_err(got, want), 1e-4) << file;
    // Other resolutions interpolate the position grid (DINO's behaviour).
    EXPECT_EQ(vit->forward(torch::zeros({1, 3, 48, 64})).sizes(), (std::vector<int64_t>{1, 16, 6, 8}));
  }
}

TEST(Teachers, PerceptualLossIsZeroForIdenticalImagesAndGrowsWithDistortion) {
  Vgg16 vgg(test::source_dir() / "tests" / "fixtures" / "vgg16_narrow.safetensors");
  torch::manual_seed(1);
  auto x = torch::rand({2, 3, 32, 48}) * 2 - 1;
  EXPECT_NEAR(perceptual_loss(vgg, x, x).item<double>(), 0, 1e-6);
  double small = perceptual_loss(vgg, x, x + 0.05 * torch::randn_like(x)).item<double>();
  double large = perceptual_loss(vgg, x, x + 0.5 * torch::randn_like(x)).item<double>();
  EXPECT_GT(small, 0);
  EXPECT_GT(large, small);
}

TEST(Teachers, MissingOrCorruptTeacherFilesAreClearErrors) {
  test::TempDir dir;
  EXPECT_THROW(Vgg16(dir / "none.safetensors"), Error);
  try {
    Vgg16 v(test::source_dir() / "tests" / "fixtures" / "vit_tv.safetensors");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("features.0.weight"), std::string::npos) << e.what();
  }
}
