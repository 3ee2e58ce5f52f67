#include "gaia/world/scaling.h"

#include <cmath>

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/eval/svg_plot.h"
#include "gaia/sizing/sizing.h"
#include "gaia/world/token_dataset.h"
#include "gaia/world/trainer.h"

namespace gaia::world {

using nlohmann::json;

std::vector<ScalingRun> scaling_family(const Config& c, int sizes, int64_t n) {
  const auto& w = c.world;
  if (sizes < 4) fail("gaia scaling: --sizes {} is too few: the fit takes 3 runs besides the largest it predicts", sizes);
  std::vector<ScalingRun> out;
  for (int k = 0; k < sizes; ++k) {
    ScalingRun r;
    const double width = w.scaling_width * std::pow(w.scaling_growth, k);
    r.d_model = std::max(1, int(std::lround(width / w.scaling_head_dim))) * w.scaling_head_dim;
    if (!out.empty() && r.d_model <= out.back().d_model) r.d_model = out.back().d_model + w.scaling_head_dim;
    r.n_heads = r.d_model / w.scaling_head_dim;
    r.n_layers = std::max(1, int(std::lround(double(r.d_model) / w.scaling_width_per_layer)));
    r.name = fmt::format("w{}-l{}", r.d_model, r.n_layers);
    Config m = c;
    m.world.d_model = r.d_model;
    m.world.n_layers = r.n_layers;
    r.params = sizing::world_params(m).non_embedding;
    const double per_step = double(w.batch_size) * w.context_steps * double(w.text_tokens + n + w.action_tokens);
    r.steps = std::max(1, int(std::ceil(w.scaling_tokens_per_param * double(r.params) / per_step)));
    r.tokens = per_step * r.steps;
    r.flops = 6.0 * double(r.params) * r.tokens;
    out.push_back(r);
  }
  return out;
}

Config scaling_config(const Config& c, const ScalingRun& r) {
  Config m = c;
  m.world.d_model = r.d_model;
  m.world.n_layers = r.n_layers;
  m.world.n_heads = r.n_heads;
  m.world.steps = r.steps;
  m.world.warmup_steps = std::min(c.world.warmup_steps, std::max(1, r.steps / 10));  // warm-up within the run
  m.validate();
  return m;
}

namespace {

json run_json(const ScalingRun& r) {
  return {{"name", r.name}, {"d_model", r.d_model}, {"n_layers", r.n_layers}, {"n_heads", r.n_heads},
          {"params", r.params}, {"steps", r.steps}, {"tokens", r.tokens}, {"flops", r.flops}, {"loss", r.loss}};
}

json fit_json(const eval::PowerLaw& f) { return {{"c", f.c}, {"a", f.a}, {"b", f.b}, {"sse", f.sse}}; }

// Trains one run to its end (or takes its recorded outcome) and fills in its loss.
void train_run(const Config& c, const ScalingOptions& o, ScalingRun& r, const std::function<void(int, int)>& on_step,
               const std::function<void(const std::string&)>& on_note) {
  const fs::path dir = o.out / "runs" / r.name, record = dir / "run.json";
  if (fs::exists(record)) {
    const json j = read_json(record);
    if (j.value("steps", 0) != r.steps || j.value("params", int64_t{0}) != r.params)
      fail("{}: records another run ({} steps, N = {}) than this config makes ({} steps, N = {}); use another --out",
           record.string(), j.value("steps", 0), j.value("params", int64_t{0}), r.steps, r.params);
    r.loss = j.at("loss").get<double>();
    r.done = true;
    return;
  }
  WorldTrainOptions t;
  t.tokens = o.tokens;
  t.out = dir;
  t.format = o.format;
  t.steps = r.steps;
  t.val_every = r.steps;  // one validation, at the end: the run's final loss
  t.val_windows = o.val_windows;
  t.calibrate = false;  // the law is of the model's own cross-entropy (§6), as the paper fits it
  auto res = train_world(scaling_config(c, r), t, [&](const WorldStepLog& l) { if (on_step) on_step(l.step, l.total); },
                         on_note);
  if (!res.last_val.contains("action"))
    fail("{}: no validation loss (the token dataset needs held-out episodes of world.context_steps steps)",
         o.tokens.string());
  r.loss = res.last_val["action"].get<double>();
  r.done = true;
  write_file_atomic(record, run_json(r).dump(2) + "\n");
}

}  // namespace

json ScalingResult::to_json() const {
  json rs = json::array();
  for (auto& r : runs) rs.push_back(run_json(r));
  return {{"runs", rs}, {"fit", fit_json(fit)}, {"formula", "loss = c + (flops / a)^b"},
          {"largest", {{"flops", runs.back().flops}, {"predicted", predicted}, {"band_5", band.lo},
                       {"band_95", band.hi}, {"outcome", runs.back().loss}, {"relative_error", relative_error}}}};
}

ScalingResult run_scaling(const Config& c, const ScalingOptions& o,
                          const std::function<void(size_t, const ScalingRun&)>& on_run,
                          const std::function<void(int, int)>& on_step,
                          const std::function<void(const std::string&)>& on_note) {
  const TokenDataset ds(o.tokens, o.format.for_training(o.tokens, c.tokenizer.codebook_size));
  ScalingResult res;
  res.runs = scaling_family(c, o.sizes, ds.tokens_per_step());
  fs::create_directories(o.out / "runs");
  const size_t last = res.runs.size() - 1;
  for (size_t i = 0; i < last; ++i) {
    if (on_run) on_run(i, res.runs[i]);
    train_run(c, o, res.runs[i], on_step, on_note);
  }
  std::vector<double> x, y;
  for (size_t i = 0; i < last; ++i) {
    x.push_back(res.runs[i].flops);
    y.push_back(res.runs[i].loss);
  }
  res.fit = eval::fit_power_law(x, y);
  const double at = res.runs[last].flops;
  res.predicted = res.fit(at);
  res.band = eval::prediction_band(x, y, res.fit, at, 400, c.run.seed);
  // The prediction is written before the largest model trains, and kept as it was when OUT is run again.
  const fs::path pf = o.out / "prediction.json";
  if (fs::exists(pf)) {
    const json p = read_json(pf);
    res.predicted = p.at("predicted").get<double>();
    res.band = {p.at("band_5").get<double>(), p.at("band_95").get<double>()};
  } else {
    write_file_atomic(pf, json({{"fit", fit_json(res.fit)}, {"flops", at}, {"run", res.runs[last].name},
                                {"predicted", res.predicted}, {"band_5", res.band.lo}, {"band_95", res.band.hi}})
                                  .dump(2) + "\n");
  }
  if (on_run) on_run(last, res.runs[last]);
  train_run(c, o, res.runs[last], on_step, on_note);
  res.relative_error = (res.runs[last].loss - res.predicted) / res.runs[last].loss;

  eval::XYSeries fitted{"runs the law is fitted to", x, y, "#4C78A8", true, {}, {}};
  eval::XYSeries held{"largest: outcome", {at}, {res.runs[last].loss}, "#E45756", true, {}, {}};
  eval::XYSeries predicted{"largest: prediction, 5-95%", {at}, {res.predicted}, "#F58518", true, {res.band.lo},
                           {res.band.hi}};
  eval::XYSeries curve{fmt::format("fit: c {:.2f}, b {:.3f}", res.fit.c, res.fit.b), {}, {}, "#54A24B", false, {}, {}};
  for (int i = 0; i <= 60; ++i) {
    const double f = std::exp(std::log(x.front()) + (std::log(at) - std::log(x.front())) * i / 60.0);
    curve.x.push_back(f);
    curve.y.push_back(res.fit(f));
  }
  write_file_atomic(o.out / "scaling.svg",
                    eval::svg_loglog("World model: validation loss against training compute (§6)",
                                     {curve, fitted, predicted, held}, "training compute C = 6 N D (FLOPs)",
                                     "validation cross-entropy (nats / image token)"));
  write_file_atomic(o.out / "scaling.json", res.to_json().dump(2) + "\n");
  return res;
}

}  // namespace gaia::world
