#include "gaia/emerging/rollouts.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/eval/svg_plot.h"
#include "gaia/world/rollout.h"

namespace gaia::emerging {

double copy_rate(const torch::Tensor& frames) {
  if (frames.size(0) < 2) return std::nan("");
  return (frames.slice(0, 1) == frames.slice(0, 0, -1)).to(torch::kFloat64).mean().item<double>();
}

double unigram_entropy_bits(const torch::Tensor& frames, int64_t K) {
  auto h = torch::bincount(frames.reshape({-1}).to(torch::kLong), {}, K).to(torch::kFloat64);
  auto p = h / h.sum();
  auto nz = p.masked_select(p > 0);
  return -(nz * nz.log2()).sum().item<double>();
}

namespace {

// Real held-out frames (decoded like the generated ones, so both pass through the same tokenizer decoder) and
// their token windows: the reference for FD-probe and for the long-rollout statistics.
struct RealReference {
  torch::Tensor features;              // [N, F] scene-probe features of decoded real frames
  std::vector<cv::Mat> frames;         // those frames, decoded
  std::vector<torch::Tensor> windows;  // token windows [W, n] of real episodes
};

RealReference real_reference(Models& m, const world::TokenDataset& ds, int64_t window, int max_frames, uint64_t seed,
                             Footage footage) {
  auto split = ds.split(0.1, seed);
  auto ids = split.held_out();
  RealReference r;
  std::vector<torch::Tensor> picks;
  for (size_t e : ds.indices(ids)) {
    if (!footage_matches(ds, e, footage)) continue;
    auto all = episode_tokens(ds, e);
    for (int64_t s = 0; s + window <= ds.steps(e); s += window) r.windows.push_back(all.narrow(0, s, window));
    for (int64_t k = 0; k < ds.steps(e); k += 5) picks.push_back(all[k]);
  }
  if (picks.empty()) fail("{}: no held-out episodes for the real reference", ds.path().string());
  std::vector<torch::Tensor> chosen;
  for (int i = 0; i < max_frames && i < int(picks.size()); ++i)
    chosen.push_back(picks[size_t(i) * picks.size() / size_t(std::min<int>(max_frames, int(picks.size())))]);
  r.frames = decode(m, torch::stack(chosen).unsqueeze(0))[0];
  read_scene(m, r.frames, &r.features);
  return r;
}

torch::Tensor scene_features(Models& m, const std::vector<cv::Mat>& frames) {
  torch::Tensor f;
  read_scene(m, frames, &f);
  return f;
}

}  // namespace

nlohmann::json futures_diversity(Models& m, const world::TokenDataset& ds, const RolloutEvalOptions& o, Output& out) {
  const int64_t P = o.prompt_frames, F = o.frames, N = o.futures;
  if (N < 2) fail("diversity needs at least two futures per prompt");
  auto pr = held_out_prompts(ds, o.prompts, P, P + F, m.info.config.run.seed, o.footage);
  world::RolloutPrompt p;
  p.tokens = pr.tokens.repeat_interleave(N, 0);
  p.actions = torch::full({o.prompts * N, P + F, 2}, std::nan(""));  // the prompt's recorded actions, then none
  p.actions.narrow(1, 0, P).copy_(pr.actions.repeat_interleave(N, 0));
  world::RolloutOptions ro;
  ro.frames = int(F);
  ro.futures = int(o.prompts * N);
  ro.sampling = o.sampling;
  ro.precision = m.precision;
  ro.seed = o.seed + 1;
  auto r = world::rollout(m.world, p, ro);
  auto gen = r.tokens.narrow(1, P, F);  // [prompts * N, F, n]
  double dist = 0;
  int pairs = 0;
  for (int i = 0; i < o.prompts; ++i)
    for (int64_t a = 0; a < N; ++a)
      for (int64_t b = a + 1; b < N; ++b, ++pairs)
        dist += (gen[i * N + a] != gen[i * N + b]).to(torch::kFloat64).mean().item<double>();
  auto frames = decode(m, r.tokens);
  std::vector<cv::Mat> generated;
  for (auto& row : frames) generated.insert(generated.end(), row.begin() + P, row.end());
  auto real = real_reference(m, ds, 1, 2 * int(generated.size()), m.info.config.run.seed, o.footage);
  const int64_t half = real.features.size(0) / 2;
  nlohmann::json j = {
      {"prompts", o.prompts}, {"futures", N}, {"frames", F},
      {"mean_pairwise_token_distance", dist / pairs},
      {"fd_probe_to_real", probe::frechet_distance(scene_features(m, generated), real.features)},
      {"fd_probe_real_vs_real", probe::frechet_distance(real.features.slice(0, 0, half), real.features.slice(0, half))}};
  if (m.realism) {
    // Whether futures stay real: the share of generated frames the realism probe reads as camera footage, beside
    // the share of the held-out frames themselves (through the same decoder): its ceiling.
    auto gen_p = read_realism(m, generated), real_p = read_realism(m, real.frames);
    j["realism"] = {{"generated_read_real", (gen_p > 0.5).to(torch::kFloat64).mean().item<double>()},
                    {"held_out_read_real", (real_p > 0.5).to(torch::kFloat64).mean().item<double>()},
                    {"generated_mean_p_real", gen_p.mean().item<double>()},
                    {"held_out_mean_p_real", real_p.mean().item<double>()},
                    {"generated_frames", gen_p.size(0)},
                    {"held_out_frames", real_p.size(0)}};
  }
  std::vector<std::vector<cv::Mat>> rows(frames.begin(), frames.begin() + std::min<int64_t>(N, 3));
  std::vector<std::string> labels;
  for (size_t i = 0; i < rows.size(); ++i) labels.push_back(fmt::format("future {}", i + 1));
  const double fps = ds.rate_hz() > 0 ? ds.rate_hz() : 6.25;
  out.gif("videos/futures.gif", tile(rows, labels), fps / 2);
  out.sections.push_back(
      {{"title", "Multiple futures"},
       {"text", fmt::format("{} futures from each of {} held-out prompts ({} prompt frames, {} generated, top-k "
                            "sampling). FD-probe is a Frechet distance on the scene probe's features (not FVD).",
                            N, o.prompts, P, F)},
       {"videos", {{{"caption", "the same prompt, three sampled futures"},
                    {"items", {{{"label", "futures"}, {"path", "videos/futures.gif"}}}}}}},
       {"metrics", j}});
  return j;
}

nlohmann::json long_rollout(Models& m, const world::TokenDataset& ds, const RolloutEvalOptions& o, Output& out) {
  const double rate = ds.rate_hz() > 0 ? ds.rate_hz() : 6.25;
  const int64_t P = o.prompt_frames, F = int64_t(std::lround(o.long_seconds * rate));
  const int64_t W = int64_t(std::lround(o.window_seconds * rate)), R = o.long_rollouts;
  if (F < W) fail("--long-seconds {} is shorter than one {} s window", o.long_seconds, o.window_seconds);
  if (R < 1) fail("--long-rollouts must be at least 1, got {}", R);
  auto pr = held_out_prompts(ds, int(R), P, P, m.info.config.run.seed, o.footage);  // spread over the held-out drives
  world::RolloutPrompt p;
  p.tokens = pr.tokens;  // [R, P, n]: one prompt per rollout
  world::RolloutOptions ro;
  ro.frames = int(F);
  ro.futures = int(R);
  ro.sampling = o.sampling;
  ro.precision = m.precision;
  ro.seed = o.seed + 2;
  ProgressBar bar(F, R > 1 ? fmt::format("long rollouts ({} at once)", R) : std::string("long rollout"));
  auto r = world::rollout(m.world, p, ro, [&](int done, int) { bar.update(done); });
  bar.finish();
  auto gen = r.tokens.narrow(1, P, F);  // [R, F, n]
  auto frames = decode(m, gen);         // [R][F]
  auto real = real_reference(m, ds, W, 256, m.info.config.run.seed, o.footage);
  if (real.windows.empty()) fail("{}: no held-out episode is {} s long (the statistics window)", ds.path().string(), o.window_seconds);
  auto mean_of = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x / double(v.size());
    return s;
  };
  // Standard error of a mean of independent draws (0 for one draw: no spread to measure).
  auto std_error = [&](const std::vector<double>& v) {
    if (v.size() < 2) return 0.0;
    const double mu = mean_of(v);
    double ss = 0;
    for (double x : v) ss += (x - mu) * (x - mu);
    return std::sqrt(ss / double(v.size() - 1) / double(v.size()));
  };
  std::vector<double> real_copies, real_entropies;
  for (auto& w : real.windows) {
    real_copies.push_back(copy_rate(w));
    real_entropies.push_back(unigram_entropy_bits(w, m.info.K));
  }
  const double real_copy = mean_of(real_copies), real_entropy = mean_of(real_entropies);
  // How much real windows themselves vary: the 10th / 50th / 90th percentile of each statistic over the real
  // windows, and the fraction of real windows within 10% of the real mean (what the per-window target would ask of
  // a single generated window, asked of real video).
  auto spread = [](std::vector<double> v, double mean) {
    std::sort(v.begin(), v.end());
    auto q = [&](double f) { return v[size_t(std::lround(f * double(v.size() - 1)))]; };
    double within = 0;
    for (double x : v)  // a zero mean (frozen real video) counts only the windows that are zero too
      within += (mean > 0 ? std::abs(x / mean - 1) <= 0.10 : x == 0) ? 1.0 / double(v.size()) : 0.0;
    return nlohmann::json{{"p10", q(0.1)}, {"p50", q(0.5)}, {"p90", q(0.9)}, {"within_10_percent_of_mean", within}};
  };
  nlohmann::json windows = nlohmann::json::array();
  std::vector<double> xs, all_copies, all_entropies;
  // Each rollout's own mean over its windows: the rollouts are independent draws, the windows of one rollout are not,
  // so the pooled figure's standard error is over these.
  std::vector<double> rollout_copies(size_t(R), 0.0), rollout_entropies(size_t(R), 0.0);
  eval::Series s_copy{"copy rate (generated)", {}, ""}, s_copy_real{"copy rate (real)", {}, ""};
  eval::Series s_ent{"entropy / 10 bits (generated)", {}, ""}, s_ent_real{"entropy / 10 bits (real)", {}, ""};
  double worst = 0;
  for (int64_t s = 0; s + W <= F; s += W) {
    std::vector<double> cs, es;  // this window of every rollout
    std::vector<cv::Mat> window_frames;
    for (int64_t k = 0; k < R; ++k) {
      auto w = gen[k].narrow(0, s, W);
      cs.push_back(copy_rate(w));
      es.push_back(unigram_entropy_bits(w, m.info.K));
      rollout_copies[size_t(k)] += cs.back() / double(F / W);
      rollout_entropies[size_t(k)] += es.back() / double(F / W);
      window_frames.insert(window_frames.end(), frames[size_t(k)].begin() + s, frames[size_t(k)].begin() + s + W);
    }
    all_copies.insert(all_copies.end(), cs.begin(), cs.end());
    all_entropies.insert(all_entropies.end(), es.begin(), es.end());
    const double c = mean_of(cs), e = mean_of(es);
    const double fd = probe::frechet_distance(scene_features(m, window_frames), real.features);
    windows.push_back({{"from_s", double(s) / rate}, {"copy_rate", c}, {"copy_rate_std_error", std_error(cs)},
                       {"copy_rate_per_rollout", cs}, {"entropy_bits", e}, {"entropy_bits_std_error", std_error(es)},
                       {"fd_probe_to_real", fd}, {"copy_rate_vs_real", c / real_copy - 1},
                       {"entropy_vs_real", e / real_entropy - 1}});
    worst = std::max({worst, std::abs(c / real_copy - 1), std::abs(e / real_entropy - 1)});
    xs.push_back(double(s) / rate);
    s_copy.y.push_back(c);
    s_copy_real.y.push_back(real_copy);
    s_ent.y.push_back(e / 10);
    s_ent_real.y.push_back(real_entropy / 10);
  }
  // Every generated window against every real one: the minute as a whole.
  const double pooled_copy = mean_of(all_copies), pooled_entropy = mean_of(all_entropies);
  const double pooled_worst = std::max(std::abs(pooled_copy / real_copy - 1), std::abs(pooled_entropy / real_entropy - 1));
  nlohmann::json j = {{"seconds", o.long_seconds},
                      {"frames", F},
                      {"rollouts", R},
                      {"prompt_episodes", std::set<size_t>(pr.episodes.begin(), pr.episodes.end()).size()},
                      {"generated_frames_per_second", double(R * F) / r.seconds},
                      {"real_copy_rate", real_copy},
                      {"real_copy_rate_std_error", std_error(real_copies)},
                      {"real_entropy_bits", real_entropy},
                      {"real_entropy_bits_std_error", std_error(real_entropies)},
                      {"real_windows", real.windows.size()},
                      {"real_copy_rate_spread", spread(real_copies, real_copy)},
                      {"real_entropy_bits_spread", spread(real_entropies, real_entropy)},
                      {"windows", windows},
                      {"pooled", {{"copy_rate", pooled_copy},
                                  {"copy_rate_std_error", std_error(rollout_copies)},
                                  {"copy_rate_vs_real", pooled_copy / real_copy - 1},
                                  {"entropy_bits", pooled_entropy},
                                  {"entropy_bits_std_error", std_error(rollout_entropies)},
                                  {"entropy_vs_real", pooled_entropy / real_entropy - 1},
                                  {"within_10_percent", pooled_worst <= 0.10}}},
                      {"max_relative_difference", worst},
                      {"within_10_percent", worst <= 0.10}};
  out.text("plots/long_rollout.svg",
           eval::svg_lines(fmt::format("token statistics per window, mean of {} long rollout{}", R, R > 1 ? "s" : ""),
                           xs, {s_copy, s_copy_real, s_ent, s_ent_real}, "seconds", ""));
  std::vector<cv::Mat> every;  // the first rollout, every other frame, played at half speed: the minute in 30 s
  for (size_t k = 0; k < frames[0].size(); k += 2) every.push_back(frames[0][k]);
  out.gif("videos/long_rollout.gif", every, rate / 2);
  out.sections.push_back(
      {{"title", "Long rollout"},
       {"text", fmt::format("{} long rollout{} of {} s, each from a {}-frame prompt of another held-out drive, with the "
                            "sliding window (context {} steps); statistics per {} s window, averaged over the "
                            "rollouts, against real held-out token episodes.",
                            R, R > 1 ? "s" : "", o.long_seconds, P, m.info.config.world.context_steps,
                            o.window_seconds)},
       {"videos", {{{"caption", "a minute of driving (the first rollout, every other frame)"},
                    {"items", {{{"label", "long rollout"}, {"path", "videos/long_rollout.gif"}}}}}}},
       {"plots", {{{"caption", "copy rate and unigram entropy per window"}, {"path", "plots/long_rollout.svg"}}}},
       {"metrics", j}});
  return j;
}

}  // namespace gaia::emerging
