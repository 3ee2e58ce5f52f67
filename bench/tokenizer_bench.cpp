// Tokenizer throughput: encode (frames -> tokens) at the default and paper resolutions, and one training step.
// Results and the PyTorch-Python comparison live in docs/benchmarks.md.
#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/tokenizer/autoencoder.h"

using namespace gaia;

static void BM_TokenizerEncode(benchmark::State& st) {
  Config c;  // default tokenizer architecture, at the requested resolution
  c.data.height = static_cast<int>(st.range(0));
  c.data.width = static_cast<int>(st.range(1));
  const int64_t B = st.range(2);
  torch::manual_seed(0);
  tokenizer::ImageTokenizer t(c);
  t->eval();
  torch::NoGradGuard ng;
  auto x = torch::rand({B, 3, c.data.height, c.data.width}) * 2 - 1;
  for (auto _ : st) benchmark::DoNotOptimize(t->tokenize(x));
  st.counters["frames/s"] = benchmark::Counter(double(B) * st.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_TokenizerEncode)->Args({72, 128, 16})->Args({288, 512, 2})->Unit(benchmark::kMillisecond)->UseRealTime();

static void BM_TokenizerTrainStep(benchmark::State& st) {
  Config c;
  const int64_t B = st.range(0);
  torch::manual_seed(0);
  tokenizer::ImageTokenizer t(c);
  torch::optim::AdamW opt(t->parameters(), torch::optim::AdamWOptions(1e-4));
  auto x = torch::rand({B, 3, c.data.height, c.data.width}) * 2 - 1;
  for (auto _ : st) {
    opt.zero_grad();
    auto o = t->forward(x);
    auto loss = (o.reconstruction - x).pow(2).mean() + o.q.codebook_loss + 0.25 * o.q.commit_loss;
    loss.backward();
    opt.step();
  }
  st.counters["frames/s"] = benchmark::Counter(double(B) * st.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_TokenizerTrainStep)->Arg(8)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
