#include "gaia/world/world_eval.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "gaia/core/error.h"
#include "gaia/eval/compress.h"
#include "gaia/eval/svg_plot.h"
#include "gaia/world/evaluate.h"

namespace gaia::world {

nlohmann::json evaluate_world(WorldModel& model, const WorldInfo& info, const TokenDataset& ds,
                              const WorldEvalOptions& o, const std::function<void(int, int)>& progress) {
  auto split = ds.split(0.1, info.config.run.seed);
  auto ids = split.held_out();
  if (ids.empty()) ids = ds.ids();  // e.g. a bare .npy: score everything (say so)
  auto eps = with_footage(ds, ds.indices(ids), o.footage);
  auto windows = validation_windows(ds, eps, info.config.world.context_steps, o.max_windows);
  // Bits per token over the held-out frames read as a stream, each frame once with the frames before it in view (as
  // the compressors read them); the per-frame measures below keep non-overlapping windows.
  auto stream = stream_windows(ds, eps, info.config.world.context_steps, o.max_windows);
  const std::string kind = o.footage == Footage::kAny ? "" : to_string(o.footage) + " ";
  if (windows.empty()) fail("{}: no held-out {}window of {} steps to score", o.name, kind, info.config.world.context_steps);
  const TextSource text = text_source(info, ds);
  nlohmann::json j = {{"tokens", o.name}, {"world", o.weights}, {"footage", to_string(o.footage)},
                      {"episodes", eps.size()}, {"windows", windows.size()}, {"stream_windows", stream.size()}};
  std::vector<int> ks = o.top_k_sweep.empty() ? std::vector<int>{1, info.config.world.top_k, 0} : o.top_k_sweep;
  for (int k : ks)
    if (k < 0 || k > info.K) fail("--top-k-sweep: k must be in [0, {}] (0 = the whole distribution), got {}", info.K, k);
  if (o.sweep_windows < 1) fail("--sweep-windows must be >= 1");
  const int total = int(7 + ks.size());
  int done = 0;
  auto step = [&] {
    if (progress) progress(++done, total);
  };
  auto run_score = [&](Conditioning mode, bool shuffle) {
    ScoreOptions so;
    so.mode = mode;
    so.shuffle = shuffle;
    so.batch = info.config.world.batch_size;
    auto s = score(model, ds, stream, text, so);
    step();
    return s;
  };
  auto act = run_score(Conditioning::kAction, false);
  auto act_shuf = run_score(Conditioning::kAction, true);
  auto txt = run_score(Conditioning::kText, false);
  auto txt_shuf = run_score(Conditioning::kText, true);
  auto unc = run_score(Conditioning::kUnconditional, false);
  // The same held-out frames (those scored, in order) through general-purpose compressors.
  std::vector<int16_t> frames;
  for (auto& w : stream) {
    auto ep = ds.episode(w.episode);
    const int64_t n = ds.tokens_per_step();
    for (int64_t t = w.start + w.scored_from; t < w.start + w.steps; ++t)
      for (int64_t i = 0; i < n; ++i) frames.push_back(static_cast<int16_t>(ep->tokens[size_t(t * n + i)]));
  }
  auto xz = eval::xz_size(frames), zs = eval::zstd_size(frames);
  const double floor = std::min(xz.bits_per_token, zs.bits_per_token);
  j["cross_entropy_nats"] = {{"action", act.nats}, {"text", txt.nats}, {"uncond", unc.nats},
                             {"action_shuffled", act_shuf.nats}, {"text_shuffled", txt_shuf.nats}};
  j["bits_per_token"] = {{"world_model", act.bits()}, {"xz", xz.bits_per_token}, {"zstd", zs.bits_per_token},
                         {"ratio_best_compressor_over_model", floor / act.bits()}};
  j["conditioning_used"] = {{"action_shuffled_minus_true_nats", act_shuf.nats - act.nats},
                            {"text_shuffled_minus_true_nats", txt_shuf.nats - txt.nats}};
  auto steer = steering_sensitivity(model, ds, windows, info.config.world.batch_size);
  step();
  auto steer_row = [](const SteeringSensitivity::Row& r) {
    return nlohmann::json{{"frames", r.frames}, {"nats", r.nats}, {"curvature_zeroed_rise_nats", r.zeroed_rise},
                          {"curvature_mirrored_rise_nats", r.mirrored_rise}};
  };
  j["steering_sensitivity"] = {{"threshold_per_m", 0.004},
                               {"left", steer_row(steer.left)},
                               {"right", steer_row(steer.right)},
                               {"straight", steer_row(steer.straight)}};
  auto exp_all = [](const std::vector<double>& v) {
    std::vector<double> e;
    for (double x : v) e.push_back(std::exp(x));
    return e;
  };
  const std::vector<double> ppl = exp_all(act.by_position);
  j["perplexity_by_position"] = ppl;
  // Fig. 5: the last frame of held-out windows, real and as each strategy draws it, scored by the model.
  const auto few = std::vector<Window>(windows.begin(), windows.begin() + long(std::min(windows.size(), o.sweep_windows)));
  const int64_t batch = info.config.world.batch_size;
  auto real_last = score_last_frame(model, ds, few, std::nullopt, batch, info.config.run.seed);
  step();
  nlohmann::json strategies = nlohmann::json::array();
  for (int k : ks) {
    SamplingOptions so;
    so.temperature = info.config.world.temperature;
    so.strategy = k == 1 ? Strategy::Argmax : k == 0 ? Strategy::Sample : Strategy::TopK;
    so.top_k = k;
    const std::string name = k == 1 ? "argmax" : k == 0 ? "sample (whole distribution)" : fmt::format("top-k, k = {}", k);
    auto g = score_last_frame(model, ds, few, so, batch, info.config.run.seed);
    step();
    // How far the draws' per-position perplexity is from the real tokens': mean |log ppl_gen - log ppl_real|.
    double gap = 0;
    for (size_t i = 0; i < g.by_position.size(); ++i) gap += std::abs(g.by_position[i] - real_last.by_position[i]);
    gap /= double(g.by_position.size());
    strategies.push_back({{"strategy", name}, {"top_k", k}, {"perplexity_by_position", exp_all(g.by_position)},
                          {"mean_nats", g.nats}, {"log_perplexity_gap", gap}, {"copy_rate", g.copy_rate}});
  }
  j["last_frame"] = {{"windows", few.size()},
                     {"temperature", info.config.world.temperature},
                     {"real", {{"perplexity_by_position", exp_all(real_last.by_position)},
                               {"mean_nats", real_last.nats},
                               {"copy_rate", real_last.copy_rate}}},
                     {"strategies", strategies}};
  return j;
}

void write_world_eval(const nlohmann::json& j, const fs::path& out) {
  fs::create_directories(out);
  write_file_atomic(out / "eval.json", j.dump(2) + "\n");
  const auto ppl = j.at("perplexity_by_position").get<std::vector<double>>();
  std::vector<double> xs;
  for (size_t i = 0; i < ppl.size(); ++i) xs.push_back(double(i));
  write_file_atomic(out / "perplexity_by_position.svg",
                    eval::svg_lines("Perplexity by token position within a frame (Fig. 5)", xs,
                                    {{"real tokens (action-conditioned)", ppl, ""}}, "token position", "perplexity"));
  const auto& last = j.at("last_frame");
  std::vector<eval::Series> lines{
      {"real tokens", last.at("real").at("perplexity_by_position").get<std::vector<double>>(), ""}};
  for (const auto& s : last.at("strategies"))
    lines.push_back({s.at("strategy").get<std::string>(), s.at("perplexity_by_position").get<std::vector<double>>(), ""});
  write_file_atomic(out / "perplexity_by_strategy.svg",
                    eval::svg_lines("Perplexity of the generated frame's tokens by position (Fig. 5)", xs, lines,
                                    "token position", "perplexity"));
}

}  // namespace gaia::world
