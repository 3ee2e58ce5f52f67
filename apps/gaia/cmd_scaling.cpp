// gaia scaling: the scaling-law study of §6 on a token dataset (world/scaling.h): a family of world models, the law
// fitted to the smaller ones, the largest predicted before it is trained, then trained and compared.
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/world/scaling.h"
#include "gaia/world/token_dataset.h"

namespace gaia::app {

void register_scaling(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "scaling", "scaling laws (§6): train a family of world models, fit loss = c + (C/a)^b to all but the largest, "
                 "predict the largest, then train it (resumable run by run)");
  auto flags = std::make_shared<SharedFlags>();
  auto o = std::make_shared<world::ScalingOptions>();
  auto tokens = std::make_shared<std::string>();
  auto format = std::make_shared<TokenFormatFlags>();
  cmd->add_option("TOKENS", *tokens, "token dataset (gaia tokenize) or other tokenizers' token files")->required();
  add_token_format_flags(cmd, format.get());
  cmd->add_option("--sizes", o->sizes, "models in the family (width and depth: the config's world.scaling_* rule)")
      ->check(number_in({4, 64}));
  cmd->add_option("--val-windows", o->val_windows, "held-out windows of each run's final validation")
      ->check(number_in({1, 1e6}));
  auto* plan_only = cmd->add_flag("--plan", "print the family (sizes, steps, compute) and train nothing");
  add_shared_flags(cmd, flags.get(), "study directory (runs/, prediction.json, scaling.json, scaling.svg)");
  cmd->callback([=] {
    Config c = resolve_config(*flags);
    apply_threads(c);
    world::ScalingOptions opt = *o;
    opt.tokens = *tokens;
    opt.format = token_format(*format, c, false);
    opt.out = flags->out;
    if (plan_only->count()) {
      const world::TokenDataset ds(opt.tokens, token_format(*format, c, !fs::exists(opt.tokens / "dataset.json")));
      std::printf("%-12s %8s %7s %6s %10s %8s %12s %10s\n", "run", "d_model", "layers", "heads", "N", "steps",
                  "tokens", "FLOPs");
      for (auto& r : world::scaling_family(c, opt.sizes, ds.tokens_per_step()))
        std::printf("%-12s %8d %7d %6d %10lld %8d %12.3g %10.3g\n", r.name.c_str(), r.d_model, r.n_layers, r.n_heads,
                    (long long)r.params, r.steps, r.tokens, r.flops);
      return;
    }
    if (flags->out.empty()) fail("gaia scaling: --out DIR is required");
    std::unique_ptr<ProgressBar> bar;
    size_t total_runs = size_t(opt.sizes);
    auto r = world::run_scaling(
        c, opt,
        [&](size_t i, const world::ScalingRun& run) {
          if (bar) bar->finish();
          bar.reset();
          std::fprintf(stderr, "scaling: run %zu/%zu %s (N = %lld, %d steps, %.3g FLOPs)\n", i + 1, total_runs,
                       run.name.c_str(), (long long)run.params, run.steps, run.flops);
        },
        [&](int step, int total) {
          if (!bar) bar = std::make_unique<ProgressBar>(total, "scaling", true, step - 1);
          bar->update(step);
        },
        [](const std::string& n) { std::fprintf(stderr, "scaling: %s\n", n.c_str()); });
    if (bar) bar->finish();
    for (auto& run : r.runs)
      std::printf("%-12s N %9lld  C %9.3g  loss %.4f\n", run.name.c_str(), (long long)run.params, run.flops, run.loss);
    std::printf("fit on %zu runs: loss = %.4f + (C / %.4g)^%.4f\n", r.runs.size() - 1, r.fit.c, r.fit.a, r.fit.b);
    std::printf("largest (%s): predicted %.4f [5-95%%: %.4f, %.4f], outcome %.4f, error %+.2f%%\n",
                r.runs.back().name.c_str(), r.predicted, r.band.lo, r.band.hi, r.runs.back().loss,
                100 * r.relative_error);
    std::printf("-> %s/scaling.json, %s/scaling.svg\n", flags->out.c_str(), flags->out.c_str());
  });
}

}  // namespace gaia::app
