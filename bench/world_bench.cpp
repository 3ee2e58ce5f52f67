// World model throughput (docs/benchmarks.md): one training step of the default config, and generating one frame
// (n tokens) with the KV cache against the naive loop that recomputes the whole context for every token.
#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/sizing/sizing.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/optim.h"
#include "gaia/world/model.h"
#include "gaia/world/rollout.h"
#include "gaia/world/token_step.h"

using namespace gaia;
using namespace gaia::world;

namespace {

Config bench_config() {
  Config c;  // default config
  // GAIA_BENCH_GLIBC_MALLOC=1 keeps glibc's default allocator settings: what configure_allocator alone is worth.
  const char* plain = std::getenv("GAIA_BENCH_GLIBC_MALLOC");
  if (!plain || std::string(plain) != "1") configure_allocator();
  if (const char* t = std::getenv("GAIA_BENCH_THREADS")) set_torch_threads(std::atoi(t));
  return c;
}

WorldBatch random_batch(const Config& c, int64_t B, int64_t T) {
  WorldBatch b;
  b.tokens = torch::randint(0, c.tokenizer.codebook_size, {B, T, c.image_tokens()}, torch::kLong);
  b.actions = torch::randn({B, T, 2});
  b.text_ids = torch::randint(0, c.world.text_vocab, {B, T, c.world.text_tokens}, torch::kLong);
  return b;
}

// The default world model with random weights (seed 0) for sampling, with a one-row cache of its whole context.
struct SamplingCase {
  Config c = bench_config();
  WorldModel m{nullptr};
  KVCache cache;
  SamplingCase() {
    torch::manual_seed(0);
    m = WorldModel(c.world, c.image_tokens(), c.tokenizer.codebook_size);
    m->eval();
    cache = m->make_cache(1, m->layout.length());
  }
  void fill(int64_t positions) { m->body(torch::randn({1, positions, m->d}), &cache); }  // under inference mode
};

}  // namespace

// Args: batch, precision (0 fp32, 1 bf16 through autocast as `gaia world train --precision bf16`).
static void BM_WorldTrainStep(benchmark::State& st) {
  Config c = bench_config();
  const int64_t B = st.range(0);
  const Precision precision = st.range(1) ? Precision::kBf16 : Precision::kFp32;
  if (precision == Precision::kBf16 && !cpu_has_bf16()) {
    st.SkipWithError("this CPU has no bf16 instructions: fp32 is the fast path");
    return;
  }
  torch::manual_seed(0);
  WorldModel m(c.world, c.image_tokens(), c.tokenizer.codebook_size);
  m->train();
  auto opt = train::make_adamw(m->parameters(), 1e-4, 0.1, 0.9, 0.95);
  auto b = random_batch(c, B, c.world.context_steps);
  for (auto _ : st) {
    opt->zero_grad();
    torch::Tensor loss;
    {
      Autocast autocast(precision, torch::kCPU);
      loss = image_token_loss(m->forward(b), b.tokens);
    }
    loss.backward();
    opt->step();
  }
  const double tokens = double(B * m->layout.length()) * double(st.iterations());
  st.counters["tokens/s"] = benchmark::Counter(tokens, benchmark::Counter::kIsRate);
  // The step's arithmetic as `gaia plan` counts it (6N + 6 L s d per token): held against BM_Peak (peak_bench.cpp)
  st.counters["FLOP/s"] = benchmark::Counter(tokens * sizing::make_plan(c).world_flops_per_token_with_attn,
                                              benchmark::Counter::kIsRate, benchmark::Counter::kIs1000);
  st.SetLabel(precision == Precision::kBf16 ? "bf16" : "fp32");
}
BENCHMARK(BM_WorldTrainStep)->Args({4, 0})->Args({4, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

// Where one generated token's time goes (a rollout is n = 144 of these per frame): the transformer body over the
// cached context (half full), the head's logits, and top-k sampling.
static void BM_TokenParts(benchmark::State& st) {
  SamplingCase sc;
  auto& c = sc.c;
  auto& m = sc.m;
  auto& cache = sc.cache;
  c10::InferenceMode im;
  const int64_t L = m->layout.length();
  sc.fill(L / 2);
  auto tok = torch::zeros({1, 1, 1}, torch::kLong);
  auto last = torch::randn({1, m->d});
  SamplingOptions so;
  so.strategy = Strategy::TopK;
  so.top_k = c.world.top_k;
  auto gen = at::detail::createCPUGenerator(0);
  const int part = int(st.range(0));
  for (auto _ : st) {
    if (part == 0 || part == 3) {  // embed + body for one token (3: the general, unfused attention)
      cache.fused_single_token = part == 0;
      cache.length = L / 2;
      benchmark::DoNotOptimize(m->body(m->embed_image(tok, 4, 3).view({1, 1, m->d}), &cache));
    } else if (part == 1) {
      benchmark::DoNotOptimize(m->logits(last));
    } else {
      benchmark::DoNotOptimize(sample_tokens(m->logits(last), so, gen));
    }
  }
  st.SetLabel(part == 0 ? "embed+body" : part == 3 ? "embed+body, unfused attention (baseline)"
                                       : part == 1 ? "logits" : "logits+top-k sample");
}
BENCHMARK(BM_TokenParts)->Arg(0)->Arg(3)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond)->UseRealTime();

// The fused token step alone (token_step.h, what a closed-loop frame runs n times on its sampling thread): one
// token through every block and the head against a cache of T - 1 steps, as after a one-step slide.
static void BM_TokenStep(benchmark::State& st) {
  SamplingCase sc;
  auto& m = sc.m;
  auto& cache = sc.cache;
  c10::InferenceMode im;
  const int64_t L = m->layout.length(), S = m->layout.per_step();
  sc.fill(L - S);
  const TokenStep step(*m);
  auto tok = torch::zeros({1}, torch::kLong);
  for (auto _ : st) {
    cache.length = L - S + 16;  // the text tokens and a few image tokens of the frame in
    benchmark::DoNotOptimize(step.logits(tok, sc.c.world.context_steps - 1, 0, cache));
  }
  st.counters["tokens/s"] = benchmark::Counter(double(st.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_TokenStep)->Unit(benchmark::kMicrosecond)->UseRealTime();

// `futures` x `frames` generated after a random prompt of T - 1 frames (the context is full for the first generated
// frame), the window dropping `stride` steps when full. Counter: generated frames per second over all futures.
static void run_rollouts(benchmark::State& st, int64_t frames, int64_t futures, int stride, bool fast = true,
                         int threads = 0) {
  Config c = bench_config();
  const int before = at::get_num_threads();
  if (threads > 0) set_torch_threads(threads);
  torch::manual_seed(0);
  WorldModel m(c.world, c.image_tokens(), c.tokenizer.codebook_size);
  RolloutPrompt p;
  const int64_t P = c.world.context_steps - 1;
  p.tokens = torch::randint(0, c.tokenizer.codebook_size, {P, c.image_tokens()}, torch::kLong);
  RolloutOptions o;
  o.frames = int(frames);
  o.futures = int(futures);
  o.window_stride = stride;
  o.lookahead = o.fused_tokens = fast;
  for (auto _ : st) benchmark::DoNotOptimize(rollout(m, p, o).tokens);
  st.counters["frames/s"] = benchmark::Counter(double(frames * futures) * st.iterations(), benchmark::Counter::kIsRate);
  set_torch_threads(before);
}

static void BM_RolloutCached(benchmark::State& st) { run_rollouts(st, st.range(0), 1, 1); }
BENCHMARK(BM_RolloutCached)->Arg(1)->Arg(8)->Unit(benchmark::kMillisecond)->UseRealTime();

// Steady state beyond the context: 16 frames, the window dropping `stride` steps when full (1 = the paper: the
// 7-step history is re-encoded after every frame).
static void BM_RolloutSliding(benchmark::State& st) { run_rollouts(st, 16, 1, int(st.range(0))); }
BENCHMARK(BM_RolloutSliding)->Arg(1)->Arg(2)->Arg(4)->Unit(benchmark::kMillisecond)->UseRealTime();

// A closed-loop session's frame (sim/): one future, the paper's one-step slide, steady state. Arg 1: as gaia sim
// runs it, one intra-op thread with the fused token step and the lookahead on a second thread; arg 0: the general
// path at GAIA_BENCH_THREADS (the baseline).
static void BM_SessionFrame(benchmark::State& st) {
  const bool fast = st.range(0) == 1;
  run_rollouts(st, 24, 1, 1, fast, fast ? 1 : 0);
  st.SetLabel(fast ? "fused token step + lookahead, 1 intra-op thread" : "general path (baseline)");
}
BENCHMARK(BM_SessionFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// A planner's candidates (SimSession::fork with plans): 4 branches of 8 frames from one full-context state of one
// session, at one intra-op thread as gaia sim runs. Arg 0: four forks stepped one after another (the baseline, and
// what SimSession::fork does on the CPU); arg 1: the four as one batch (RolloutStepper::repeat). Counter: generated frames per second over all branches.
static void BM_SessionBranches(benchmark::State& st) {
  Config c = bench_config();
  const int before = at::get_num_threads();
  set_torch_threads(1);
  torch::manual_seed(0);
  WorldModel m(c.world, c.image_tokens(), c.tokenizer.codebook_size);
  const int64_t P = c.world.context_steps - 1, branches = 4, frames = 8;
  RolloutPrompt p;
  p.tokens = torch::randint(0, c.tokenizer.codebook_size, {P, c.image_tokens()}, torch::kLong);
  RolloutOptions o;
  RolloutStepper session(m, o, 1);
  for (int64_t k = 0; k < P; ++k) session.step(p, p.tokens[k]);
  const bool batched = st.range(0) == 1;
  for (auto _ : st) {
    if (batched) {
      auto b = session.repeat(branches);
      for (int64_t f = 0; f < frames; ++f) b.step(p);
      benchmark::DoNotOptimize(b.tokens());
    } else {
      for (int64_t i = 0; i < branches; ++i) {
        auto b = session.fork();
        for (int64_t f = 0; f < frames; ++f) b.step(p);
        benchmark::DoNotOptimize(b.tokens());
      }
    }
  }
  st.counters["frames/s"] = benchmark::Counter(double(branches * frames) * st.iterations(), benchmark::Counter::kIsRate);
  st.SetLabel(batched ? "4 branches as one batch" : "4 forks one after another (baseline)");
  set_torch_threads(before);
}
BENCHMARK(BM_SessionBranches)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);

// N futures in one batch (what `gaia eval` and `--futures N` do): one decoding step serves every row, so the
// per-token dispatch cost is shared.
static void BM_RolloutBatched(benchmark::State& st) { run_rollouts(st, 1, st.range(0), 1); }
BENCHMARK(BM_RolloutBatched)->Arg(4)->Arg(16)->Arg(64)->Unit(benchmark::kMillisecond)->UseRealTime();

// The naive baseline: every new token runs the whole sequence so far through the transformer again.
static void BM_RolloutRecompute(benchmark::State& st) {
  Config c = bench_config();
  torch::manual_seed(0);
  WorldModel m(c.world, c.image_tokens(), c.tokenizer.codebook_size);
  m->eval();
  torch::NoGradGuard ng;
  const int64_t P = c.world.context_steps - 1, n = c.image_tokens(), d = c.world.d_model;
  auto prompt = random_batch(c, 1, P);
  prompt.actions.reset();
  prompt.text_ids.reset();
  SamplingOptions so;
  auto gen = at::detail::createCPUGenerator(0);
  for (auto _ : st) {
    WorldBatch step;
    step.tokens = torch::zeros({1, 1, n}, torch::kLong);
    auto ctx = m->embed(prompt);                                        // [1, P * S, d]
    auto text = m->embed_text(step, P).view({1, m->layout.m, d});
    std::vector<torch::Tensor> parts{ctx, text};
    for (int64_t i = 0; i < n; ++i) {
      auto h = m->body(torch::cat(parts, 1));                           // full recompute
      auto tok = sample_tokens(m->logits(h.select(1, h.size(1) - 1)), so, gen);
      parts.push_back(m->embed_image(tok.view({1, 1, 1}), P, i).view({1, 1, d}));
    }
    benchmark::DoNotOptimize(parts.back());
  }
  st.counters["frames/s"] = benchmark::Counter(double(st.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_RolloutRecompute)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

BENCHMARK_MAIN();
