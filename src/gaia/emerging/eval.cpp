#include "gaia/emerging/eval.h"

#include <fmt/format.h>

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/report/report.h"

namespace gaia::emerging {

std::set<std::string> parse_parts(const std::string& only) {
  std::set<std::string> parts;
  for (size_t a = 0; a <= only.size();) {
    size_t b = only.find(',', a);
    if (b == std::string::npos) b = only.size();
    auto p = only.substr(a, b - a);
    if (p != "action" && p != "text" && p != "futures" && p != "long")
      fail("--only: unknown part '{}' (action, text, futures, long)", p);
    parts.insert(p);
    a = b + 1;
  }
  return parts;
}

namespace {

// The likelihood side from `gaia world eval`: bits/token against the compressors and Fig. 5, first in the report.
void add_world_eval(const fs::path& we, nlohmann::json& j, Output& out) {
  auto wj = read_json(we / "eval.json");
  j["world_model"] = wj;
  nlohmann::json sec = {{"title", "World model likelihood"},
                        {"text", "Held-out cross-entropy of the image tokens, against xz -9 and zstd -19 on the "
                                 "same token stream, and with the conditioning shuffled across examples."},
                        {"metrics", wj}};
  sec["plots"] = nlohmann::json::array();
  for (auto [file, caption] : {std::pair{"perplexity_by_position.svg", "perplexity by token position (Fig. 5)"},
                               std::pair{"perplexity_by_strategy.svg",
                                         "the last frame drawn by argmax, top-k and full sampling against the "
                                         "real one, perplexity by position (Fig. 5)"}})
    if (fs::exists(we / file)) {
      out.text(std::string("plots/") + file, read_file(we / file));
      sec["plots"].push_back({{"caption", caption}, {"path", std::string("plots/") + file}});
    }
  out.sections.insert(out.sections.begin(), sec);
}

// Training curves and data plots, copied in so that the run directory stays self-contained.
void add_training(const std::vector<std::string>& metrics, const std::vector<std::string>& extra, Output& out) {
  nlohmann::json curves = nlohmann::json::array(), plots = nlohmann::json::array();
  for (const auto& kv : metrics) {
    const auto eq = kv.find('=');
    if (eq == std::string::npos) fail("--metrics: expected NAME=FILE, got '{}'", kv);
    const std::string name = kv.substr(0, eq), rel = "curves/" + name + ".jsonl";
    const std::string text = read_file(kv.substr(eq + 1));
    out.text(rel, text);
    // The loss, and whichever validation figures this trainer writes (train/step_loop.h metrics.jsonl).
    nlohmann::json keys = {text.find("\"losses\":") != std::string::npos ? "losses.loss" : "loss"};
    if (text.find("\"val\":{\"loss\":") != std::string::npos) keys.push_back("val.loss");
    for (const char* k : {"bits_per_token", "x0_psnr", "psnr"})
      if (text.find(fmt::format("\"{}\":", k)) != std::string::npos) keys.push_back(fmt::format("val.{}", k));
    curves.push_back({{"caption", name}, {"path", rel}, {"keys", keys}});
  }
  for (const auto& p : extra) {
    const std::string rel = "plots/extra-" + fs::path(p).filename().string();
    out.text(rel, read_file(p));
    plots.push_back({{"caption", fs::path(p).filename().string()}, {"path", rel}});
  }
  nlohmann::json sec = {{"title", "Training"}, {"text", "Loss curves of the training runs and data statistics."}};
  if (!curves.empty()) sec["curves"] = curves;
  if (!plots.empty()) sec["plots"] = plots;
  out.sections.push_back(sec);
}

}  // namespace

nlohmann::json run_eval(Models& m, const world::TokenDataset& ds, const data::Dataset* raw, const EvalOptions& o,
                        const fs::path& dir, const std::function<void(int, int, const std::string&)>& progress) {
  Output out;
  out.dir = dir;
  fs::create_directories(out.dir);
  nlohmann::json j = o.header;
  const int total = int(o.parts.size());
  int done = 0;
  auto step = [&](const std::string& what) {
    if (progress) progress(++done, total, what);
  };
  if (o.parts.count("action")) {
    j["action_control"] = action_control(m, ds, raw, o.action, out);
    step("action control");
  }
  if (o.parts.count("text")) {
    j["text_control"] = text_control(m, o.text, out, &ds);
    step("text control");
  }
  if (o.parts.count("futures")) {
    j["futures"] = futures_diversity(m, ds, o.rollouts, out);
    step("futures");
  }
  if (o.parts.count("long")) {
    step("long rollout");  // counted before it starts: it draws its own progress bar
    j["long_rollout"] = long_rollout(m, ds, o.rollouts, out);
  }
  if (!o.world_eval.empty()) add_world_eval(o.world_eval, j, out);
  if (!o.metrics.empty() || !o.plots.empty()) add_training(o.metrics, o.plots, out);
  for (auto& s : out.sections) s["commands"] = {o.command_line};
  write_file_atomic(out.dir / "eval.json", j.dump(2) + "\n");
  nlohmann::json manifest = {{"title", "gaia evaluation"},
                             {"subtitle", "emerging properties of the world model, measured (GAIA-1 §5)"},
                             {"sections", out.sections}};
  write_file_atomic(out.dir / "report.json", manifest.dump(2) + "\n");
  report::write_report(out.dir, out.dir / "report.html");
  return j;
}

}  // namespace gaia::emerging
