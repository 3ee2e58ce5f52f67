// Mixed precision (torch/precision.h): autocast regions and their float32 islands, fp16's loss scale, the VQ
// distance kept in float32, and bf16 world-model training that tracks float32's loss.
#include <cmath>

#include "gaia/core/npy.h"
#ifndef GAIA_NO_VIDEO
#include "gaia/tokenizer/quantizer.h"
#endif
#include "gaia/torch/attention.h"
#include "gaia/torch/precision.h"
#include "test_util.h"

using namespace gaia;
using test::q;

TEST(Precision, AutocastRegionsNestAndRestore) {
  const torch::Device cpu(torch::kCPU), dev(test::device_name());
  torch::nn::Linear lin(8, 4);
  lin->to(dev);
  auto x = torch::randn({2, 8}, dev);
  EXPECT_EQ(lin(x).scalar_type(), torch::kFloat);
  {
    Autocast bf16(Precision::kBf16, dev);
    EXPECT_EQ(lin(x).scalar_type(), torch::kBFloat16);
    {
      Autocast fp32(Precision::kFp32, dev);  // a float32 island inside
      EXPECT_EQ(lin(x).scalar_type(), torch::kFloat);
    }
    EXPECT_EQ(lin(x).scalar_type(), torch::kBFloat16);
  }
  EXPECT_EQ(lin(x).scalar_type(), torch::kFloat);

  EXPECT_EQ(parse_precision("bf16"), Precision::kBf16);
  EXPECT_NE(test::error_of([] { parse_precision("int8"); }).find("'int8'"), std::string::npos);
  EXPECT_NE(test::error_of([&] { precision_for("fp16", cpu); }).find("needs a CUDA device"), std::string::npos);
}

TEST(Precision, LossScaleHalvesOnOverflowAndGrowsAfterGoodSteps) {
  LossScaler fp16(Precision::kFp16, 1024, 3);
  EXPECT_TRUE(fp16.active());
  EXPECT_FALSE(fp16.update(false));
  EXPECT_EQ(fp16.scale(), 512);
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(fp16.update(true));
  EXPECT_EQ(fp16.scale(), 1024);
  LossScaler bf16(Precision::kBf16);
  EXPECT_FALSE(bf16.active());
  EXPECT_EQ(bf16.scale(), 1);
  EXPECT_FALSE(bf16.update(false));
  EXPECT_EQ(bf16.scale(), 1);
}

#ifndef GAIA_NO_VIDEO
TEST(Precision, QuantizerPicksTheFloat32CodesUnderBf16) {
  const torch::Device dev(test::device_name());
  torch::manual_seed(0);
  tokenizer::VectorQuantizer vq(32, 16, 1024);
  vq->to(dev);
  auto z = torch::randn({2, 32, 6, 8}, dev);
  auto want = vq(z).indices;
  tokenizer::QuantizerOutput got;
  {
    Autocast bf16(Precision::kBf16, dev);
    got = vq(z);
  }
  EXPECT_TRUE(torch::equal(got.indices, want));
  EXPECT_EQ(got.z_q.scalar_type(), torch::kFloat);
}
#endif

TEST(Precision, AttentionUnderBf16StaysNearFloat32) {
  const torch::Device dev(test::device_name());
  // Without bf16 instructions (or with LibTorch's kernels capped below them, as the suite's AVX2 pass does, where
  // oneDNN then has no bf16 products at all) gaia runs bf16 as fp32: precision_for, PrecisionCli.
  if (dev.is_cpu() && !cpu_has_bf16()) GTEST_SKIP() << "this CPU runs --precision bf16 as fp32 (no bf16 instructions)";
  torch::manual_seed(1);
  auto o = torch::TensorOptions().device(dev);
  auto q = torch::randn({2, 3, 16, 8}, o), k = torch::randn({2, 3, 16, 8}, o), v = torch::randn({2, 3, 16, 8}, o);
  auto want = attention(q, k, v, {}, true);
  torch::Tensor got;
  {
    Autocast bf16(Precision::kBf16, dev);
    got = attention(q, k, v, {}, true).to(torch::kFloat);
  }
  EXPECT_LT((got - want).abs().max().item<double>(), 0.05);
}

TEST(PrecisionCli, Bf16WorldTrainingTracksFloat32) {
  test::TempDir dir;
  torch::manual_seed(3);
  // Tokens with structure to learn (each frame repeats the one before, with a few changes), on a 4x8 grid, K = 64.
  auto t = torch::randint(0, 64, {1, 4, 8}, torch::kLong).repeat({160, 1, 1});
  auto change = torch::rand({160, 4, 8}) < 0.2;
  t = torch::where(change, torch::randint(0, 64, {160, 4, 8}, torch::kLong), t).contiguous();
  npy_write(dir / "tokens.npy", npy_make(DType::I64, {160, 4, 8},
                                         std::vector<int64_t>(t.data_ptr<int64_t>(), t.data_ptr<int64_t>() + t.numel())));
  const std::string common = "world train " + q(dir / "tokens.npy") + " --grid 4x8 --codebook-size 64 --config " +
                           q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1 --val-every 0" +
                           " --device " + test::device_name();
  const std::string base = common + " --steps 40";
  auto r = test::run_gaia(base + " --out " + q(dir / "fp32"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(base + " --precision bf16 --out " + q(dir / "bf16"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto a = test::jsonl_numbers(dir / "fp32" / "metrics.jsonl", "loss");
  const auto b = test::jsonl_numbers(dir / "bf16" / "metrics.jsonl", "loss");
  ASSERT_EQ(a.size(), 40u);
  ASSERT_EQ(b.size(), 40u);
  EXPECT_LT(a.back(), a.front() - 0.3);  // float32 learns something ...
  const bool emulated = test::device_name() == "cpu" && !cpu_has_bf16();
  EXPECT_EQ(r.output.find("no bf16 instructions") != std::string::npos, emulated) << r.output;
  if (emulated) {  // ... and a CPU without bf16 instructions trains in fp32, saying so: the same run exactly
    EXPECT_EQ(a, b);
  } else {  // ... and bf16 the same
    double worst = 0;
    for (size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
    EXPECT_LT(worst, 0.05) << "bf16 loss left float32's by " << worst << " nats";
  }
  // Sampling under bf16 too (the KV-cached one-token attention stays float32 inside).
  r = test::run_gaia("generate " + q(dir / "tokens.npy") + " --grid 4x8 --codebook-size 64 --world " +
                     q(dir / "bf16" / "world.safetensors") + " --frames 3 --futures 2 --precision bf16 --threads 1" +
                     " --device " + test::device_name() + " --out " + q(dir / "gen"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("generated 3 frames x 2 futures"), std::string::npos) << r.output;
  // Capped below bf16's instructions (as the suite's AVX2 pass runs), bf16 falls back whatever the CPU has.
  r = test::run_shell("ATEN_CPU_CAPABILITY=avx2 " + test::gaia_command(common + " --steps 2 --precision bf16 --out " +
                                                                       q(dir / "capped")) + " 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  if (test::device_name() == "cpu")
    EXPECT_NE(r.output.find("running in fp32 instead"), std::string::npos) << r.output;
  r = test::run_gaia(base + " --precision fp16 --out " + q(dir / "fp16"));
  if (test::device_name() == "cpu") {
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.output.find("--precision fp16 needs a CUDA device"), std::string::npos) << r.output;
  } else {  // fp16 with its loss scale tracks float32 too
    ASSERT_EQ(r.status, 0) << r.output;
    const auto h = test::jsonl_numbers(dir / "fp16" / "metrics.jsonl", "loss");
    ASSERT_EQ(h.size(), 40u);
    for (size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], h[i], 0.05) << "fp16 step " << i + 1;
  }
  r = test::run_gaia(base + " --precision fp8 --out " + q(dir / "fp8"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("run.precision 'fp8'"), std::string::npos) << r.output;
}
