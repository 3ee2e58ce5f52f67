#include "gaia/emerging/text.h"

#include <cmath>
#include <map>

#include "gaia/core/error.h"
#include "gaia/eval/svg_plot.h"
#include "gaia/world/prompt_text.h"
#include "gaia/world/rollout.h"

namespace gaia::emerging {

std::vector<TextTarget> text_targets() {
  return {{0, "rain", "heavy rain", "clear skies"},   {0, "fog", "thick fog", "clear skies"},
          {0, "snow", "falling snow", "clear skies"}, {0, "clear", "clear skies", "heavy rain"},
          {1, "night", "night", "daytime"},           {1, "dusk", "dusk", "daytime"},
          {1, "day", "daytime", "night"},             {2, "red", "red light ahead", "green light ahead"},
          {2, "green", "green light ahead", "red light ahead"}};
}

namespace {

const char* kAttributes[] = {"weather", "time_of_day", "light"};

const std::vector<std::string>& classes(int attribute) {
  return attribute == 0 ? probe::weather_classes() : attribute == 1 ? probe::time_classes() : probe::light_classes();
}

struct Run {
  std::string name;
  world::GuidanceSchedule guidance;
  bool negative = false;
};

}  // namespace

nlohmann::json real_decoded_accuracy(Models& m, const world::TokenDataset& ds, const std::vector<size_t>& episodes,
                                     int frames_per_episode) {
  if (frames_per_episode < 1) fail("real_decoded_accuracy: frames_per_episode must be >= 1");
  const auto targets = text_targets();
  std::map<std::string, std::pair<double, double>> hits;  // prompted value -> (frames read as it, frames)
  int used = 0;
  for (size_t e : episodes) {
    const auto& meta = ds.meta(e);
    const int64_t S = ds.steps(e);
    if (S < 1) continue;
    std::vector<const TextTarget*> mine;  // the prompted values this episode shows
    for (const auto& t : targets)
      if ((t.attribute == 0 && t.value == meta.weather) || (t.attribute == 1 && t.value == meta.time_of_day))
        mine.push_back(&t);
    if (mine.empty()) continue;
    auto all = episode_tokens(ds, e);
    std::vector<int64_t> steps;
    for (int k = 0; k < frames_per_episode; ++k) steps.push_back(std::min<int64_t>(S - 1, k * S / frames_per_episode));
    auto frames = decode(m, all.index_select(0, torch::tensor(steps)).unsqueeze(0))[0];
    auto cls = read_scene(m, frames);  // [F, 4]
    for (const auto* t : mine) {
      const int want = probe::class_index(classes(t->attribute), t->value);
      auto& h = hits[t->value];
      h.first += double(cls.select(1, t->attribute).eq(want).sum().item<int64_t>());
      h.second += double(frames.size());
    }
    ++used;
  }
  nlohmann::json j = {{"frames", frames_per_episode}, {"episodes", used}, {"per_target", nlohmann::json::object()}};
  for (int a = 0; a < 2; ++a) {
    double sum = 0;
    int count = 0;
    for (const auto& t : targets) {
      auto it = hits.find(t.value);
      if (t.attribute != a || it == hits.end()) continue;
      j["per_target"][t.value] = it->second.first / it->second.second;
      sum += it->second.first / it->second.second;
      ++count;
    }
    j[kAttributes[a]] = count ? nlohmann::json(sum / count) : nlohmann::json(nullptr);
  }
  return j;
}

nlohmann::json text_control(Models& m, const TextEvalOptions& o, Output& out, const world::TokenDataset* real) {
  const int64_t P = o.prompt_frames;
  std::vector<TextTarget> targets;
  for (const auto& t : text_targets())
    if (P == 0 || t.attribute < 2) targets.push_back(t);  // a recorded drive's traffic lights are not labelled
  const int64_t G = int64_t(targets.size()), N = G * o.futures, F = o.frames, M = m.info.config.world.text_tokens;
  std::vector<std::string> prompts, negatives;
  for (int64_t r = 0; r < N; ++r) {
    prompts.push_back(targets[size_t(r / o.futures)].prompt);
    negatives.push_back(targets[size_t(r / o.futures)].negative);
  }
  world::RolloutPrompt p, with_negative;
  nlohmann::json j;
  if (P > 0) {
    // Row r: target r / futures from held-out daytime prompt r % futures, with its recorded actions, then none.
    if (!real) fail("text control from prompts needs the token dataset");
    auto pr = held_out_prompts(*real, o.futures, P, P + F, m.info.config.run.seed, o.prompt_footage,
                               [&](size_t e) { return real->meta(e).time_of_day == "day"; });
    p.tokens = pr.tokens.repeat({G, 1, 1});
    p.actions = torch::full({N, P + F, 2}, std::nan(""));
    p.actions.narrow(1, 0, P).copy_(pr.actions.repeat({G, 1, 1}));
    j["prompt_frames"] = P;
    j["prompt_episodes"] = nlohmann::json::array();
    for (size_t e : pr.episodes) j["prompt_episodes"].push_back(real->ids()[e]);
  }
  // The text holds from the first step: a prompt shown with its own words would only be continued.
  world::set_future_texts(p, m.text_encoder(), prompts, P + F, M);
  world::set_future_texts(with_negative, m.text_encoder(), negatives, P + F, M, true);
  std::vector<Run> runs;
  for (double s : o.scales) runs.push_back({fmt::format("s = {}", s), {s}, false});
  const double top = o.scales.empty() ? 2.0 : o.scales.back();
  runs.push_back({fmt::format("s = {}, negative prompt", top), {top}, true});
  world::GuidanceSchedule sched{top, world::GuidanceSchedule::Tokens::Linear, world::GuidanceSchedule::Frames::Cosine,
                                1, int(F)};
  runs.push_back({fmt::format("s = {}, linear over tokens, cosine over frames", top), sched, false});

  j["targets"] = G;
  j["futures"] = o.futures;
  j["frames"] = F;
  std::vector<eval::Series> curves(3);
  const int attributes = P > 0 ? 2 : 3;
  curves.resize(size_t(attributes));
  for (int a = 0; a < attributes; ++a) curves[size_t(a)].name = kAttributes[a];
  std::vector<std::vector<cv::Mat>> best_rows;
  std::vector<std::string> best_labels;
  nlohmann::json table = nlohmann::json::array();
  for (size_t ri = 0; ri < runs.size(); ++ri) {
    const auto& run = runs[ri];
    world::RolloutPrompt q = p;
    if (run.negative) {
      q.negative_text_ids = with_negative.negative_text_ids;
      q.negative_text_emb = with_negative.negative_text_emb;
    }
    world::RolloutOptions ro;
    ro.frames = int(F);
    ro.futures = int(N);
    ro.sampling = o.sampling;
    ro.precision = m.precision;
    ro.guidance = run.guidance;
    ro.guidance.total_frames = int(F);
    ro.seed = o.seed + 17 * ri;
    auto r = world::rollout(m.world, q, ro);
    auto frames = decode(m, r.tokens.narrow(1, P, F));  // the generated frames only
    std::vector<double> hit(3, 0), total(3, 0);
    nlohmann::json per = nlohmann::json::object(), read_as = nlohmann::json::object();
    for (int64_t g = 0; g < G; ++g) {
      const auto& t = targets[size_t(g)];
      const auto& names = classes(t.attribute);
      const int want = probe::class_index(names, t.value);
      std::vector<double> got(names.size(), 0.0);  // frames read as each class: what a missed prompt looks like
      for (int f = 0; f < o.futures; ++f) {
        auto read = read_scene(m, frames[size_t(g * o.futures + f)]).select(1, t.attribute).cpu();  // [F]
        auto cls = read.accessor<int64_t, 1>();
        for (int64_t k = 0; k < F; ++k) got[size_t(cls[k])] += 1;
      }
      const double n = double(o.futures * F), h = got[size_t(want)];
      per[t.value] = h / n;
      read_as[t.value] = nlohmann::json::object();
      for (size_t c = 0; c < names.size(); ++c)
        if (got[c] > 0) read_as[t.value][names[c]] = got[c] / n;
      hit[size_t(t.attribute)] += h;
      total[size_t(t.attribute)] += n;
    }
    nlohmann::json row = {{"setting", run.name}, {"per_target", per}, {"read_as", read_as}};
    for (int a = 0; a < 3; ++a) {
      if (total[size_t(a)] == 0) continue;  // not prompted (traffic lights on real prompts)
      row[kAttributes[a]] = hit[size_t(a)] / total[size_t(a)];
      if (ri < o.scales.size()) curves[size_t(a)].y.push_back(hit[size_t(a)] / total[size_t(a)]);
    }
    table.push_back(row);
    if (ri + 1 == o.scales.size()) {  // the highest plain scale: one future per target for the video
      for (int64_t g = 0; g < G; ++g) {
        best_rows.push_back(frames[size_t(g * o.futures)]);
        best_labels.push_back(targets[size_t(g)].prompt);
      }
    }
  }
  j["runs"] = table;
  out.text("plots/text_guidance.svg", eval::svg_lines("prompted attribute read back by the scene probe", o.scales,
                                                      curves, "guidance scale s", "accuracy"));
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& r : table)
    rows.push_back({r["setting"], r["weather"], r["time_of_day"], r.value("light", nlohmann::json(nullptr))});
  if (real) {  // what the probe reads on real scenes of the prompted kinds: the most a prompt can score
    j["real_decoded"] =
        real_decoded_accuracy(m, *real, real->indices(real->split(0.1, m.info.config.run.seed).held_out()), 16);
    rows.push_back({"real held-out frames through the same decoder (the probe's ceiling)", j["real_decoded"]["weather"],
                    j["real_decoded"]["time_of_day"], nullptr});
  }
  std::vector<std::vector<cv::Mat>> top_row(best_rows.begin(), best_rows.begin() + std::min<size_t>(5, best_rows.size()));
  std::vector<std::vector<cv::Mat>> bottom_row(best_rows.begin() + std::min<size_t>(5, best_rows.size()), best_rows.end());
  std::vector<cv::Mat> video = tile(top_row, best_labels);
  if (!bottom_row.empty()) {
    auto b = tile(bottom_row, std::vector<std::string>(best_labels.begin() + 5, best_labels.end()));
    for (size_t k = 0; k < video.size() && k < b.size(); ++k) {
      cv::Mat pad = cv::Mat::zeros(b[k].rows, video[k].cols, video[k].type());
      b[k].copyTo(pad(cv::Rect(0, 0, std::min(b[k].cols, pad.cols), b[k].rows)));
      cv::vconcat(video[k], pad, video[k]);
    }
  }
  out.gif("videos/text_prompts.gif", video, 3.0);
  out.sections.push_back(
      {{"title", "Text control"},
       {"text", P > 0 ? fmt::format("Held-out {} daytime drives ({} frames each) continued under a text prompt "
                                    "({} prompts x {} futures x {} frames); the scene probe reads the prompted "
                                    "attribute back from every generated frame.",
                                    o.prompt_footage == Footage::kReal ? "recorded" : "procedural", P, G, o.futures, F)
                      : fmt::format("Scenes generated from a text prompt alone ({} prompts x {} futures x {} frames); "
                                    "the scene probe reads the prompted attribute back from every decoded frame.",
                                    G, o.futures, F)},
       {"videos", {{{"caption", fmt::format("one future per prompt at guidance s = {}", top)},
                    {"items", {{{"label", "text prompts"}, {"path", "videos/text_prompts.gif"}}}}}}},
       {"plots", {{{"caption", "accuracy of the prompted attribute vs guidance scale"},
                   {"path", "plots/text_guidance.svg"}}}},
       {"tables", {{{"caption", "accuracy of the prompted attribute"},
                    {"columns", {"setting", "weather", "time of day", "light"}}, {"rows", rows}}}}});
  return j;
}

}  // namespace gaia::emerging
