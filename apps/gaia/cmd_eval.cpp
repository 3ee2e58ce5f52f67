// gaia eval: the paper's emerging properties measured (§5): action control against the counterfactual replay,
// text control against the guidance scale, diversity of futures, and a minute-long rollout; results as eval.json,
// plots, videos and the report manifest (report.json) that `gaia report` turns into one HTML page.
#include <cstdio>

#include "common.h"
#include "gaia/emerging/eval.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::app {

namespace {

struct EvalFlags {
  std::string tokens, world, tokenizer, dataset, dynamics_probe = "models/probe-dynamics.safetensors",
      scene_probe = "models/probe-scene.safetensors", only = "action,text,futures,long", world_eval,
      action_negative = "mirror", commands = "default", t5, prompt_footage = "any", realism_probe;
  int prompts = 8, prompt_frames = 3, frames = 5, futures = 4, text_frames = 4, top_k = -1;
  int long_rollouts = emerging::RolloutEvalOptions{}.long_rollouts;
  double action_guidance = 0, long_seconds = 60, window_seconds = 10;
  std::vector<double> scales = emerging::TextEvalOptions{}.scales;
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
  add_weights_flag(cmd, Weights::T5, &e->t5, "encodes text control's prompts for a world model trained on its embeddings");
  auto old_dataset = add_old_spelling(cmd, "--dataset", "the positional EPISODES");
  cmd->add_option("--dynamics-probe", e->dynamics_probe, "dynamics probe weights (default: the shipped one)");
  cmd->add_option("--scene-probe", e->scene_probe, "scene probe weights (default: the shipped one)");
  cmd->add_option("--only", e->only, "comma-separated parts: action, text, futures, long");
  add_footage_flag(cmd, "--prompt-footage", &e->prompt_footage,
                   "which held-out episodes give the video prompts and the real reference (a dataset of both measures "
                   "each apart; with real, text control continues held-out recorded daytime drives under its prompts)");
  cmd->add_option("--realism-probe", e->realism_probe,
                  "realism probe weights (probe-realism.safetensors): futures also report the share of generated "
                  "frames read as real, beside the held-out frames' own share");
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
      ->check(CLI::IsMember(emerging::kCommandSets));
  cmd->add_option("--scales", e->scales,
                  "guidance scales for text control (default 0,1,2,4,8; the last also runs with the negative prompt "
                  "and with the schedules)")
      ->delimiter(',')
      ->check(key_range("world.guidance_scale"));
  auto text_from_prompts = std::make_shared<bool>(false);
  cmd->add_flag("--text-from-prompts", *text_from_prompts,
                "text control continues held-out daytime drives of --prompt-footage (--prompt-frames steps) under each "
                "weather and time-of-day prompt instead of generating from nothing; --prompt-footage real always does");
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
    const auto parts = emerging::parse_parts(e->only);
    if (parts.count("long") && e->long_rollouts < 1)  // before any model is loaded or part is run
      fail("--long-rollouts must be at least 1, got {}", e->long_rollouts);
    auto dev = parse_device(run.run.device);
    auto m = emerging::load_models(e->world, e->tokenizer, e->dynamics_probe, e->scene_probe, dev, e->t5);
    if (!e->realism_probe.empty()) emerging::load_realism_probe(m, e->realism_probe);
    m.precision = run_precision(run, dev, "eval");  // the rollouts'; the probes read their frames in float32
    apply_sampling_sets(*flags, "world", kWorldSamplingKeys, e->world, m.info.config);  // --top-k still wins
    world::TokenDataset ds(e->tokens, m.info.K);
    if (ds.tokens_per_step() != m.info.n())
      fail("{}: {} tokens per frame, the world model takes {}", e->tokens, ds.tokens_per_step(), m.info.n());
    std::unique_ptr<data::Dataset> raw;
    if (!e->dataset.empty()) raw = std::make_unique<data::Dataset>(e->dataset);
    else if (parts.count("action")) std::printf("note: no EPISODES dataset: action control without the counterfactual replay\n");

    emerging::EvalOptions o;
    o.parts = parts;
    world::SamplingOptions sampling;
    sampling.top_k = e->top_k > 0 ? e->top_k : m.info.config.world.top_k;  // paper §5.1: top-k sampling
    sampling.temperature = m.info.config.world.temperature;
    sampling.guide_actions_within_top_k = m.info.config.world.guide_actions_within_top_k;
    o.header = {{"world", e->world},        {"tokenizer", e->tokenizer},
                {"tokens", e->tokens},      {"top_k", sampling.top_k},
                {"prompt_footage", e->prompt_footage},
                {"temperature", sampling.temperature},
                {"guide_actions_within_top_k", sampling.guide_actions_within_top_k},
                {"precision", to_string(m.precision)}};
    o.action.prompts = e->prompts;
    o.action.prompt_frames = e->prompt_frames;
    o.action.frames = e->frames;
    o.action.sampling = sampling;
    o.action.guidance_scale = e->action_guidance;
    o.action.mirror_negative = e->action_negative == "mirror";
    o.action.commands = e->commands;
    o.action.seed = uint64_t(run.run.seed);
    o.action.footage = o.rollouts.footage = world::parse_footage(e->prompt_footage);
    o.text.futures = e->futures;
    o.text.frames = e->text_frames;
    o.text.scales = e->scales;
    o.text.sampling = sampling;
    o.text.seed = uint64_t(run.run.seed);
    if (o.action.footage == world::Footage::kReal || *text_from_prompts) {  // text steering a scene in view
      o.text.prompt_frames = e->prompt_frames;
      o.text.prompt_footage = o.action.footage;
    }
    o.rollouts.prompts = e->prompts;
    o.rollouts.prompt_frames = e->prompt_frames;
    o.rollouts.frames = e->frames;
    o.rollouts.futures = e->futures;
    o.rollouts.long_seconds = e->long_seconds;
    o.rollouts.window_seconds = e->window_seconds;
    o.rollouts.long_rollouts = e->long_rollouts;
    o.rollouts.sampling = sampling;
    o.rollouts.seed = uint64_t(run.run.seed);
    o.world_eval = e->world_eval;
    o.metrics = e->metrics;
    o.plots = e->plots;
    o.command_line = g_command_line;
    ProgressBar bar(int64_t(parts.size()), "eval");
    auto j = emerging::run_eval(m, ds, raw.get(), o, flags->out, [&](int done, int total, const std::string& what) {
      bar.update(done, what);
      if (done == total) bar.finish();
    });
    bar.finish();
    const fs::path out_dir = flags->out;
    std::printf("%s\nwrote %s/eval.json and %s/report.html\n", j.dump(2).c_str(), out_dir.c_str(), out_dir.c_str());
  });
}

}  // namespace gaia::app
