// Rendering and simulation throughput of the procedural world (docs/synth.md, "Performance").
//   synth_bench --benchmark_filter=Synth
// BM_SynthRender/<h>/<w>/<naive>: naive=1 is the reference renderer (exact exp() fog per pixel instead of
// the lookup table), the baseline for the optimised path.
#include <benchmark/benchmark.h>

#include "gaia/synth/synth.h"

namespace gs = gaia::synth;

namespace {

// Renders frames of six episodes cycling through weathers and times of day, stepping the world in between
// (the step is excluded from the timing).
void BM_SynthRender(benchmark::State& state) {
  const char* weathers[] = {"clear", "overcast", "rain", "fog", "snow"};
  const char* tods[] = {"day", "dusk", "night"};
  std::vector<std::unique_ptr<gs::Simulator>> sims;
  for (int e = 0; e < 6; ++e) {
    gs::SynthOptions o;
    o.height = static_cast<int>(state.range(0));
    o.width = static_cast<int>(state.range(1));
    o.seed = 1;
    o.weather = weathers[e % 5];
    o.time_of_day = tods[e % 3];
    o.seconds = 60;
    sims.push_back(std::make_unique<gs::Simulator>(o, e));
    sims.back()->renderer().set_naive(state.range(2) != 0);
  }
  cv::Mat img;
  int64_t i = 0;
  for (auto _ : state) {
    gs::Simulator& sim = *sims[static_cast<size_t>(i % 6)];
    sim.renderer().render(sim.world(), img);
    benchmark::DoNotOptimize(img.data);
    state.PauseTiming();
    sim.step(sim.policy());
    state.ResumeTiming();
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["frames/s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SynthRender)->Args({72, 128, 0})->Args({72, 128, 1})->Args({288, 512, 0})->Args({288, 512, 1})->Unit(benchmark::kMillisecond);

// World simulation only (policy + agents + ego), no rendering.
void BM_SynthStep(benchmark::State& state) {
  gs::SynthOptions o;
  o.seed = 2;
  o.district = "city";
  o.seconds = 600;
  gs::Simulator sim(o, 0);
  for (auto _ : state) sim.step(sim.policy());
  state.counters["steps/s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SynthStep);

}  // namespace

BENCHMARK_MAIN();
