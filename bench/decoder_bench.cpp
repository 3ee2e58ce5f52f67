// Video decoder cost (docs/benchmarks.md): one DDIM step of one window (T' = 7 frames at 72x128, default config), one
// training step (batch 2), each with temporal attention below full resolution (the CPU default) and at every level
// (Ho et al. 2022), and the baseline the decoder replaces: the tokenizer's decoder on the same 7 frames.
#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/decoder/diffusion.h"
#include "gaia/decoder/unet.h"
#include "gaia/sizing/sizing.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/optim.h"

using namespace gaia;
using namespace gaia::decoder;

namespace {

Config bench_config(bool temporal_full_res) {
  Config c;  // default config
  configure_allocator();
  if (const char* t = std::getenv("GAIA_BENCH_THREADS")) set_torch_threads(std::atoi(t));
  if (temporal_full_res) c.decoder.temporal_levels = {0, 1, 2};
  return c;
}

DenoiserInput input(const Config& c, int64_t B) {
  const int64_t T = c.decoder.frames, H = c.data.height, W = c.data.width, D = c.tokenizer.downsample;
  DenoiserInput in;
  in.x = torch::randn({B, T, 3, H, W});
  in.context = torch::zeros({B, T});
  in.tokens = torch::randint(0, c.tokenizer.codebook_size, {B, T, H / D, W / D}, torch::kLong);
  in.cond_image = torch::randn({B, T, 3, H, W});
  in.time = torch::full({B, T}, 0.5);
  in.rate = torch::zeros({B}, torch::kLong);
  return in;
}

}  // namespace

// Args: temporal attention at every level (1) or the default levels 1, 2 (0); the products in float32 (0) or under
// bf16 autocast (1, as `gaia decode --precision bf16`). FLOP/s: the pass's FLOPs as `gaia plan` counts them.
static void BM_DecoderDdimStep(benchmark::State& st) {
  Config c = bench_config(st.range(0) == 1);
  torch::manual_seed(0);
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  m->eval();
  torch::NoGradGuard ng;
  Autocast autocast(st.range(1) == 1 ? Precision::kBf16 : Precision::kFp32, torch::kCPU);
  auto in = input(c, 1);
  for (auto _ : st) benchmark::DoNotOptimize(m->forward(in));
  st.counters["frames/s"] = benchmark::Counter(double(c.decoder.frames) * st.iterations(), benchmark::Counter::kIsRate);
  st.counters["FLOP/s"] = benchmark::Counter(sizing::inference_flops(c, 1).decoder_window * double(st.iterations()),
                                             benchmark::Counter::kIsRate);
}
BENCHMARK(BM_DecoderDdimStep)->Args({0, 0})->Args({1, 0})->Args({0, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

// Where a pass's time goes: the default U-Net (arg 0), its temporal layers off (1), and no spatial attention either
// (2), in float32.
static void BM_DecoderPassParts(benchmark::State& st) {
  Config c = bench_config(false);
  if (st.range(0) == 2) c.decoder.attn_levels = {};
  torch::manual_seed(0);
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  m->eval();
  torch::NoGradGuard ng;
  auto in = input(c, 1);
  in.temporal = st.range(0) == 0;
  for (auto _ : st) benchmark::DoNotOptimize(m->forward(in));
}
BENCHMARK(BM_DecoderPassParts)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

// One of the full-resolution 3x3 convolutions (32 channels over T' = 7 frames at 72x128), NCHW (arg 0) or
// channels-last (1).
static void BM_DecoderConv(benchmark::State& st) {
  Config c = bench_config(false);
  const int64_t ch = c.decoder.channels;
  torch::nn::Conv2d conv(torch::nn::Conv2dOptions(ch, ch, 3).padding(1));
  torch::NoGradGuard ng;
  auto x = torch::randn({c.decoder.frames, ch, c.data.height, c.data.width});
  if (st.range(0) == 1) x = x.contiguous(at::MemoryFormat::ChannelsLast);
  for (auto _ : st) benchmark::DoNotOptimize(conv(x));
}
BENCHMARK(BM_DecoderConv)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

static void BM_DecoderTrainStep(benchmark::State& st) {
  Config c = bench_config(st.range(0) == 1);
  torch::manual_seed(0);
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  m->train();
  auto opt = train::make_adamw(m->parameters(), 1e-4, 0.01, 0.9, 0.99);
  auto in = input(c, c.decoder.batch_size);
  auto target = torch::randn_like(in.x);
  for (auto _ : st) {
    opt->zero_grad();
    auto loss = v_loss(m->forward(in), target, 1 - in.context, 0.1, 1.0);
    loss.backward();
    opt->step();
  }
}
BENCHMARK(BM_DecoderTrainStep)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// Baseline: the tokenizer's own decoder (`gaia decode --fast`) on the same 7 frames' tokens.
static void BM_TokenizerDecode7(benchmark::State& st) {
  Config c = bench_config(false);
  torch::manual_seed(0);
  tokenizer::ImageTokenizer t(c);
  t->eval();
  torch::NoGradGuard ng;
  const int64_t D = c.tokenizer.downsample;
  auto ids = torch::randint(0, c.tokenizer.codebook_size, {c.decoder.frames, c.data.height / D, c.data.width / D}, torch::kLong);
  for (auto _ : st) benchmark::DoNotOptimize(t->decode_tokens(ids));
  st.counters["frames/s"] = benchmark::Counter(double(c.decoder.frames) * st.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_TokenizerDecode7)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
