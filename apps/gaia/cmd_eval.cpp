// gaia eval: the paper's emerging properties measured (§5): action control against the counterfactual replay,
// text control against the guidance scale, diversity of futures, and a minute-long rollout; results as eval.json,
// plots, videos and the report manifest (report.json) that `gaia report` turns into one HTML page.
#include <cstdio>
#include <set>

#include "common.h"
#include "gaia/control/action.h"
#include "gaia/control/rollouts.h"
#include "gaia/control/text.h"
#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/core/progress.h"
#include "gaia/report/report.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::app {

namespace {

struct EvalFlags {
  std::string tokens, world, tokenizer, dataset, dynamics_probe = "models/probe-dynamics.safetensors",
      scene_probe = "models/probe-scene.safetensors", only = "action,text,futures,long", world_eval,
      action_negative = "mirror", commands = "default";
  int prompts = 8, prompt_frames = 3, frames = 5, futures = 4, text_frames = 4, top_k = -1;
  int long_rollouts = control::RolloutEvalOptions{}.long_rollouts;
  double action_guidance = 0, long_seconds = 60, window_seconds = 10;
  std::vector<double> scales = control::TextEvalOptions{}.scales;
  std::vector<std::string> metrics, plots;  // NAME=metrics.jsonl of training runs; extra SVG plots
};

}  // namespace

void register_eval(CLI::App& app) {
  auto* cmd = app.add_subcommand("eval", "measure action control, text control, futures and long rollouts (§5)");
  auto flags = std::make_shared<SharedFlags>();
  auto e = std::make_shared<EvalFlags>();
  cmd->add_option("TOKENS", e->tokens, "token dataset (gaia tokenize): held-out episodes give the prompts")->required();
  cmd->add_option("EPISODES", e->dataset,
                  "the procedural episode dataset the tokens came from (gaia synth): action control's counterfactual "
                  "replay");
  add_weights_flag(cmd, Weights::World, &e->world)->required();
  add_weights_flag(cmd, Weights::Tokenizer, &e->tokenizer, "decodes the rollouts")->required();
  auto old_dataset = add_old_spelling(cmd, "--dataset", "the positional EPISODES");
  cmd->add_option("--dynamics-probe", e->dynamics_probe, "dynamics probe weights (default: the shipped one)");
  cmd->add_option("--scene-probe", e->scene_probe, "scene probe weights (default: the shipped one)");
  cmd->add_option("--only", e->only, "comma-separated parts: action, text, futures, long");
  cmd->add_option("--prompts", e->prompts, "held-out video prompts")->check(number_in({1, 1e6}));
  cmd->add_option("--prompt-frames", e->prompt_frames, "prompt frames per rollout")->check(number_in({1, 1e6}));
  cmd->add_option("--frames", e->frames, "generated frames per rollout (action control, futures)")->check(number_in({1, 1e6}));
  cmd->add_option("--futures", e->futures, "futures per prompt (diversity) and per text prompt and setting")->check(number_in({1, 1e6}));
  cmd->add_option("--text-frames", e->text_frames, "frames generated from each text prompt")->check(number_in({1, 1e6}));
  cmd->add_option("--top-k", e->top_k, "k for top-k sampling (default: the world model's config world.top_k)")
      ->check(key_range("world.top_k"));
  cmd->add_option("--action-guidance", e->action_guidance,
                  "classifier-free guidance scale on the commanded actions (action control; 0 = off)")
      ->check(key_range("world.guidance_scale"));
  cmd->add_option("--action-negative", e->action_negative,
                  "the unconditional branch of action guidance: mirror (the counter-command: turning the other way, "
                  "at the kept speed; default) or null (no actions, eq. 2 as in the paper)")
      ->check(CLI::IsMember({"null", "mirror"}));
  cmd->add_option("--commands", e->commands,
                  "action control's commands: default (straight, left, right, strong-left, strong-right, drift-right, "
                  "slow, fast) or sweep (the steering response curve: 8 to 40 1/km right, 8 to 30 1/km left)")
      ->check(CLI::IsMember(control::kCommandSets));
  cmd->add_option("--scales", e->scales,
                  "guidance scales for text control (default 0,1,2,4,8; the last also runs with the negative prompt "
                  "and with the schedules)")
      ->delimiter(',')
      ->check(key_range("world.guidance_scale"));
  cmd->add_option("--long-seconds", e->long_seconds, "length of the long rollout (sliding window)")->check(number_in({0, 1e6, true, false}));
  cmd->add_option("--window-seconds", e->window_seconds, "statistics window of the long rollout")->check(number_in({0, 1e6, true, false}));
  cmd->add_option("--long-rollouts", e->long_rollouts,
                  "long rollouts, each from another held-out prompt, run as one batch; their window statistics are "
                  "averaged (one drive's windows vary as much as real drives do)")->check(number_in({1, 1e6}));
  cmd->add_option("--metrics", e->metrics, "NAME=RUN/metrics.jsonl of a training run: its loss curves go in the report")
      ->take_all();
  cmd->add_option("--plot", e->plots, "an extra SVG plot for the report (e.g. the balance.svg of gaia data stats)")
      ->take_all();
  cmd->add_option("--world-eval", e->world_eval, "a `gaia world eval` output directory to include in the report");
  add_shared_flags(cmd, flags.get(), "output directory (eval.json, report.json, report.html, plots/, videos/)");
  cmd->callback([=] {
    old_spelling_into(*old_dataset, e->dataset);
    Config run = resolve_config(*flags);
    apply_threads(run);
    if (flags->out.empty()) fail("gaia eval: --out DIR is required");
    std::set<std::string> parts;
    for (size_t a = 0; a <= e->only.size();) {
      size_t b = e->only.find(',', a);
      if (b == std::string::npos) b = e->only.size();
      auto p = e->only.substr(a, b - a);
      if (p != "action" && p != "text" && p != "futures" && p != "long")
        fail("--only: unknown part '{}' (action, text, futures, long)", p);
      parts.insert(p);
      a = b + 1;
    }
    if (parts.count("long") && e->long_rollouts < 1)  // before any model is loaded or part is run
      fail("--long-rollouts must be at least 1, got {}", e->long_rollouts);
    auto dev = parse_device(run.run.device);
    auto m = control::load_models(e->world, e->tokenizer, e->dynamics_probe, e->scene_probe, dev);
    apply_sampling_sets(*flags, "world", kWorldSamplingKeys, e->world, m.info.config);  // --top-k still wins
    world::TokenDataset ds(e->tokens, m.info.K);
    if (ds.tokens_per_step() != m.info.n())
      fail("{}: {} tokens per frame, the world model takes {}", e->tokens, ds.tokens_per_step(), m.info.n());
    std::unique_ptr<data::Dataset> raw;
    if (!e->dataset.empty()) raw = std::make_unique<data::Dataset>(e->dataset);
    else if (parts.count("action")) std::printf("note: no --dataset: action control without the counterfactual replay\n");

    control::Output out;
    out.dir = flags->out;
    fs::create_directories(out.dir);
    world::SamplingOptions sampling;
    sampling.top_k = e->top_k > 0 ? e->top_k : m.info.config.world.top_k;  // paper §5.1: top-k sampling
    sampling.temperature = m.info.config.world.temperature;
    sampling.guide_actions_within_top_k = m.info.config.world.guide_actions_within_top_k;
    nlohmann::json j = {{"world", e->world},        {"tokenizer", e->tokenizer},
                        {"tokens", e->tokens},      {"top_k", sampling.top_k},
                        {"temperature", sampling.temperature},
                        {"guide_actions_within_top_k", sampling.guide_actions_within_top_k}};
    ProgressBar bar(int64_t(parts.size()), "eval");
    int done = 0;
    if (parts.count("action")) {
      control::ActionEvalOptions o;
      o.prompts = e->prompts;
      o.prompt_frames = e->prompt_frames;
      o.frames = e->frames;
      o.sampling = sampling;
      o.guidance_scale = e->action_guidance;
      o.mirror_negative = e->action_negative == "mirror";
      o.commands = e->commands;
      o.seed = uint64_t(run.run.seed);
      j["action_control"] = control::action_control(m, ds, raw.get(), o, out);
      bar.update(++done, "action control");
    }
    if (parts.count("text")) {
      control::TextEvalOptions o;
      o.futures = e->futures;
      o.frames = e->text_frames;
      o.scales = e->scales;
      o.sampling = sampling;
      o.seed = uint64_t(run.run.seed);
      j["text_control"] = control::text_control(m, o, out, &ds);
      bar.update(++done, "text control");
    }
    control::RolloutEvalOptions ro;
    ro.prompts = e->prompts;
    ro.prompt_frames = e->prompt_frames;
    ro.frames = e->frames;
    ro.futures = e->futures;
    ro.long_seconds = e->long_seconds;
    ro.window_seconds = e->window_seconds;
    ro.long_rollouts = e->long_rollouts;
    ro.sampling = sampling;
    ro.seed = uint64_t(run.run.seed);
    if (parts.count("futures")) {
      j["futures"] = control::futures_diversity(m, ds, ro, out);
      bar.update(++done, "futures");
    }
    if (parts.count("long")) {
      bar.finish();
      j["long_rollout"] = control::long_rollout(m, ds, ro, out);
    }
    bar.finish();
    if (!e->world_eval.empty()) {
      // The likelihood side from `gaia world eval`: bits/token against the compressors and Fig. 5.
      fs::path we = e->world_eval;
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
    if (!e->metrics.empty() || !e->plots.empty()) {
      // Training curves and data plots, copied in so that the run directory stays self-contained.
      nlohmann::json curves = nlohmann::json::array(), plots = nlohmann::json::array();
      for (const auto& kv : e->metrics) {
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
      for (const auto& p : e->plots) {
        const std::string rel = "plots/extra-" + fs::path(p).filename().string();
        out.text(rel, read_file(p));
        plots.push_back({{"caption", fs::path(p).filename().string()}, {"path", rel}});
      }
      nlohmann::json sec = {{"title", "Training"}, {"text", "Loss curves of the training runs and data statistics."}};
      if (!curves.empty()) sec["curves"] = curves;
      if (!plots.empty()) sec["plots"] = plots;
      out.sections.push_back(sec);
    }
    for (auto& s : out.sections) s["commands"] = {g_command_line};
    write_file_atomic(out.dir / "eval.json", j.dump(2) + "\n");
    nlohmann::json manifest = {{"title", "gaia evaluation"},
                               {"subtitle", "emerging properties of the world model, measured (GAIA-1 §5)"},
                               {"sections", out.sections}};
    write_file_atomic(out.dir / "report.json", manifest.dump(2) + "\n");
    report::write_report(out.dir, out.dir / "report.html");
    std::printf("%s\nwrote %s/eval.json and %s/report.html\n", j.dump(2).c_str(), out.dir.c_str(), out.dir.c_str());
  });
}

}  // namespace gaia::app
