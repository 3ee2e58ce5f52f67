// gaia train-all: the recipe that makes every model of models/ from nothing: procedural data, tokenizer
// (+ a fine-tune without the GAN term, whose adversarial gradient a CPU-sized batch cannot balance), tokens, world model, video decoder, both probes,
// their evaluations, and optionally the fp16 copies for models/. With --data it runs on the user's ingested drives
// instead (mixed with procedural ones when asked; from the shipped models with --from). Each stage is this binary
// run as a child process with its own progress bar; every stage resumes from its checkpoint and a finished stage is
// skipped, so an interrupted recipe continues where it stopped.
#include <chrono>
#include <cstdio>
#include <functional>

#include <nlohmann/json.hpp>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/data/episode.h"
#include "gaia/data/manifest.h"

namespace gaia::app {

namespace {

struct Stage {
  std::string name;
  std::vector<std::string> args;  // after "gaia"
  fs::path done;                  // the stage is finished when this exists
  bool write_done = false;        // the command leaves no single final file: write `done` when it succeeds
  std::function<void()> in_process = {};  // instead of a child process (args then only describe it)
};

// OUT/data: the user's episodes (linked, never copied or changed) and their split, in a dataset that procedural
// drives can be added to.
void link_dataset(const fs::path& from, const fs::path& to) {
  data::Dataset src(from);
  data::ensure_dataset(to);
  fs::create_directories(to / "episodes");
  for (const auto& id : src.ids()) {
    const fs::path link = to / "episodes" / id;
    if (!fs::exists(fs::symlink_status(link))) fs::create_directory_symlink(fs::absolute(from / "episodes" / id), link);
  }
  if (fs::exists(from / "split.json")) fs::copy_file(from / "split.json", to / "split.json", fs::copy_options::overwrite_existing);
}

std::string joined(const std::vector<std::string>& a) {
  std::string s = "gaia";
  for (auto& x : a) s += " " + (x.find(' ') != std::string::npos ? "'" + x + "'" : x);
  return s;
}

}  // namespace

void register_train_all(CLI::App& app) {
  auto* cmd = app.add_subcommand("train-all", "the whole recipe: data, tokenizer, tokens, world model, decoder, probes, eval");
  auto flags = std::make_shared<SharedFlags>();
  auto episodes = std::make_shared<int>(160);
  auto seconds = std::make_shared<double>(30);
  auto wander_episodes = std::make_shared<int>(80);
  auto wander = std::make_shared<double>(1.2);
  auto swerve_episodes = std::make_shared<int>(80);
  auto swerve = std::make_shared<double>(0.035);
  auto ship = std::make_shared<std::string>();
  auto skip_eval = std::make_shared<bool>(false);
  auto user_data = std::make_shared<std::string>(), from = std::make_shared<std::string>();
  auto manifest = std::make_shared<std::string>();
  auto synth_mix = std::make_shared<int>(0);
  auto new_codes = std::make_shared<bool>(false);
  // Steps of each stage, each stage one run.
  struct Steps {
    int tokenizer = 0, finetune = 15000, refine = 9000, world = 3000, world_cf = 800, world_cf_rounds = 2, decoder = 1300,
        probe_scene = 2500, probe_dynamics = 4000, probe_realism = 1500;
  };
  auto st = std::make_shared<Steps>();
  cmd->add_option("--episodes", *episodes, "procedural episodes to render");
  cmd->add_option("--seconds", *seconds, "seconds per episode (recipe: 30)");
  cmd->add_option("--wander-episodes", *wander_episodes,
                  "further episodes whose driver wanders in its lane (recipe: 80; docs/synth.md: without them the "
                  "recorded steering is the road's and nothing learns to read it from the actions or the frames)");
  cmd->add_option("--wander", *wander, "their lateral wander, m (recipe: 1.2)");
  cmd->add_option("--swerve-episodes", *swerve_episodes,
                  "further wandering episodes whose driver also swerves off its lane and back (recipe: 80; they show "
                  "the world model the strong turns and drifts that gaia eval commands)");
  cmd->add_option("--swerve", *swerve, "their largest swerve curvature, 1/m (recipe: 0.035)");
  cmd->add_option("--data", *user_data, "your dataset (gaia ingest): tokenizer, tokens, world model and video decoder "
                  "on your drives instead of procedural ones (no probes or gaia eval: they need labelled drives)");
  cmd->add_option("--manifest", *manifest, "with --data: DIR is a folder of clips and this CSV their manifest (gaia "
                  "ingest --manifest): the clips are ingested with motion from the video, the procedural recipe's "
                  "drives mixed in, clips held out by source and place, and the models fine-tuned from --from "
                  "(default: the procedural recipe run first under OUT/procedural): the real-footage release");
  auto* synth_opt = cmd->add_option("--synth", *synth_mix, "with --data: also this many procedural drives (of --seconds) mixed in "
                                    "(with --manifest: default --episodes, plus the wandering and swerving drives)")
      ->check(number_in({0, 1e6}));
  cmd->add_option("--from", *from, "with --data: fine-tune the models in this directory (e.g. models: its "
                  "tokenizer's decoder only, so the codes stay, unless --new-codes; world model and decoder from their weights) instead "
                  "of training from nothing; for a user with little data");
  cmd->add_flag("--new-codes", *new_codes, "with --from: fine-tune the tokenizer's encoder and codebook too, not its "
                "decoder alone: codes fitted to your frames (the world model and video decoder then learn them from "
                "their --from weights)");
  cmd->add_option("--ship", *ship, "also write fp16 copies of the final weights into this directory (e.g. models)");
  cmd->add_flag("--skip-eval", *skip_eval, "train only");
  cmd->add_option("--tokenizer-steps", st->tokenizer, "tokenizer steps (0 = config tokenizer.steps)");
  cmd->add_option("--finetune-steps", st->finetune, "tokenizer fine-tune steps without the GAN term");
  cmd->add_option("--refine-steps", st->refine,
                  "tokenizer decoder-only steps with refinement and token blocks added (0 = no such stage)");
  cmd->add_option("--world-steps", st->world, "world model steps");
  cmd->add_option("--world-cf-steps", st->world_cf,
                  "world model fine-tune steps with counterfactual replays added (recipe: 800; 0 = no such stage, "
                  "the world model of the first phase is calibrated and shipped)");
  cmd->add_option("--world-cf-rounds", st->world_cf_rounds,
                  "rounds of that fine-tune, each from the last one's weights with a fresh warm-up, all held to the "
                  "first phase's predictions (recipe: 2, as the shipped model was made)");
  auto* decoder_opt = cmd->add_option("--decoder-steps", st->decoder,
                                      "video decoder steps (recipe: 1300; with --from: the --from decoder kept as it is "
                                      "(0 steps) while the codes stay, 300 fine-tune steps with --new-codes)")
                          ->check(number_in({0, 1e9}));
  cmd->add_option("--probe-steps", st->probe_scene, "scene probe steps");
  cmd->add_option("--dynamics-probe-steps", st->probe_dynamics, "dynamics probe steps");
  cmd->add_option("--realism-probe-steps", st->probe_realism, "realism probe steps (with --data and procedural drives)");
  add_shared_flags(cmd, flags.get(), "run directory (one folder per stage; default: runs/default)");
  cmd->callback([=] {
    Config c = resolve_config(*flags);  // validates --config / --set before hours of work start
    if (user_data->empty() && (*synth_mix > 0 || !from->empty() || !manifest->empty()))
      fail("--synth, --from and --manifest go with --data DIR");
    if (*new_codes && from->empty() && manifest->empty()) fail("--new-codes goes with --from (or --manifest)");
    auto synth_given = [synth_opt] { return synth_opt->count() > 0; };
    if (!manifest->empty()) {
      // A folder of clips: the manifest is read (and every value checked) before hours of work start.
      if (!fs::is_directory(*user_data)) fail("--data {}: not a folder of clips", *user_data);
      *manifest = fs::absolute(data::find_manifest(*manifest, *user_data)).string();
      (void)data::read_manifest(*manifest, *user_data);
      if (!from->empty())
        for (const char* f : {"tokenizer.safetensors", "world.safetensors", "decoder.safetensors"})
          if (!fs::exists(fs::path(*from) / f)) fail("--from {}: no {} there", *from, f);
    } else if (!user_data->empty()) {
      // Your drives: checked before anything runs (a dataset, of the config's frame size).
      data::Dataset mine(*user_data);
      if (mine.size() == 0) fail("{}: no episodes (gaia ingest adds them)", *user_data);
      const auto m0 = mine.meta(0);
      if (m0.height != c.data.height || m0.width != c.data.width)
        fail("{}: episodes are {}x{}, the config's data size is {}x{} (--config the dataset was ingested with)",
             *user_data, m0.height, m0.width, c.data.height, c.data.width);
      if (!from->empty())
        for (const char* f : {"tokenizer.safetensors", "world.safetensors", "decoder.safetensors"})
          if (!fs::exists(fs::path(*from) / f)) fail("--from {}: no {} there", *from, f);
    }
    const fs::path out = flags->out.empty() ? fs::path("runs/default") : fs::path(flags->out);
    DirLock lock(out);  // one train-all per --out (each stage also locks its own directory)
    std::vector<std::string> common;
    if (!flags->config.empty()) common.insert(common.end(), {"--config", flags->config});
    for (auto& s : flags->sets) common.insert(common.end(), {"--set", s});
    if (!flags->device.empty()) common.insert(common.end(), {"--device", flags->device});
    if (flags->threads >= 0) common.insert(common.end(), {"--threads", std::to_string(flags->threads)});
    auto with = [&](std::vector<std::string> a) {
      a.insert(a.end(), common.begin(), common.end());
      return a;
    };
    if (st->world_cf < 0) fail("--world-cf-steps must be >= 0, got {}", st->world_cf);
    if (st->world_cf_rounds < 1) fail("--world-cf-rounds must be >= 1, got {}", st->world_cf_rounds);
    if (*wander_episodes < 0) fail("--wander-episodes must be >= 0, got {}", *wander_episodes);
    if (*swerve_episodes < 0) fail("--swerve-episodes must be >= 0, got {}", *swerve_episodes);
    const std::string seed = std::to_string(c.run.seed);
    // Further procedural drives into `dataset`, right after its `first` lane-keeping ones (docs/synth.md):
    // wandering, then wandering and swerving. Each is its own resumable stage with its own episode indices.
    auto more_drives = [&](const std::string& dataset, int first) {
      std::vector<Stage> v;
      auto drives = [&](const std::string& kind, int n, int at, std::vector<std::string> driver) {
        if (n == 0) return;
        std::vector<std::string> a{"synth", "--episodes", std::to_string(n), "--first", std::to_string(at),
                                   "--seconds", fmt::format("{}", *seconds), "--seed", "1"};
        a.insert(a.end(), driver.begin(), driver.end());
        a.insert(a.end(), {"--out", dataset});
        v.push_back({"data-" + kind, with(a), fs::path(dataset) / (".complete-" + kind), true});
      };
      drives("wander", *wander_episodes, first, {"--wander", fmt::format("{}", *wander)});
      drives("swerve", *swerve_episodes, first + *wander_episodes,
             {"--wander", fmt::format("{}", *wander), "--swerve", fmt::format("{}", *swerve)});
      return v;
    };
    // Counterfactual replays of the lane-keeping training drives of `dataset` under held random steering commands
    // (synth/counterfactual.h: what a command does from the states a prompt shows), tokenized into `tokens`.
    auto counterfactuals = [&](const fs::path& out, const std::string& dataset, const std::string& tok,
                               const std::string& tokens) {
      const std::string cf = (out / "synth-cf").string();
      return std::vector<Stage>{
          {"data-counterfactuals",
           with({"synth", "counterfactuals", dataset, "--without-meta", "synth_wander", "--per-episode", "6", "--lead",
                 "1.5", "--hold", "2", "--max-curvature", "0.045", "--out", cf}),
           out / "synth-cf" / ".complete", true},
          {"tokens-cf", with({"tokenize", cf, "--tokenizer", tok, "--mirror", "--out", tokens}),
           fs::path(tokens) / ".complete-cf", true}};
    };
    // The procedural recipe under `out`; `ship`: also fp16 copies of its five models there.
    auto procedural = [&](const fs::path& out, const std::string& ship) {
      const std::string synth = (out / "synth").string(), tok_ft = (out / "tokenizer-ft" / "tokenizer.safetensors").string();
      const std::string tok = st->refine > 0 ? (out / "tokenizer-refine" / "tokenizer.safetensors").string() : tok_ft;
      const std::string tokens = (out / "tokens").string();
      // The fine-tune's rounds write world-cf, world-cf2, ...
      auto cf_dir = [&](int round) { return out / (round == 1 ? std::string("world-cf") : fmt::format("world-cf{}", round)); };
      const fs::path first_phase = out / "world" / "world.safetensors";  // the world model before any fine-tune
      const std::string trained = st->world_cf > 0 ? (cf_dir(st->world_cf_rounds) / "world.safetensors").string() : first_phase.string();
      const std::string world = (out / "world-calibrated" / "world.safetensors").string();
      const std::string decoder = (out / "decoder" / "decoder.safetensors").string();
      // A tokenizer run from earlier weights without the GAN term (AdamW 2e-4, 100 warm-up steps, cosine to 1e-5).
      auto no_gan_run = [&](const std::string& init, int steps, const std::string& dir, std::vector<std::string> extra) {
        std::vector<std::string> a{"tokenizer", "train", synth, "--init", init, "--steps", std::to_string(steps)};
        a.insert(a.end(), extra.begin(), extra.end());
        a.insert(a.end(), {"--set", "tokenizer.disc_start=1000000", "--set", "tokenizer.lr=2e-4", "--set",
                           "tokenizer.warmup_steps=100", "--set", "tokenizer.final_lr=1e-5", "--out", (out / dir).string()});
        return with(a);
      };
      std::vector<Stage> stages = {
          {"data", with({"synth", "--episodes", std::to_string(*episodes), "--seconds", fmt::format("{}", *seconds),
                         "--seed", "1", "--out", synth}),
           out / "synth" / ".complete", true},
          {"tokenizer", with({"tokenizer", "train", synth, "--steps", std::to_string(st->tokenizer > 0 ? st->tokenizer : c.tokenizer.steps),
                              "--out", (out / "tokenizer").string()}),
           out / "tokenizer" / "tokenizer.safetensors"},
          {"tokenizer-ft", no_gan_run((out / "tokenizer" / "tokenizer.safetensors").string(), st->finetune, "tokenizer-ft", {}),
           tok_ft},
          // Every drive also in mirror image (data/mirror.h): the world model sees as many right turns as left ones.
          {"tokens", with({"tokenize", synth, "--tokenizer", tok, "--mirror", "--out", tokens}), out / "tokens" / "dataset.json"},
          {"world", with({"world", "train", tokens, "--steps", std::to_string(st->world), "--out", (out / "world").string()}),
           first_phase},
          // world.copy_bias fitted on the lane-keeping drives, the kind gaia demo and gaia eval roll out: long rollouts
          // then copy from frame to frame as often as the real drives do.
          {"world-calibrate",
           with({"world", "calibrate", tokens, "--world", trained, "--without-meta", "synth_wander", "--without-meta",
                 "replay_of", "--out", world}),
           world},
          {"decoder",
           with({"decoder", "train", synth, "--tokenizer", tok, "--steps", std::to_string(st->decoder), "--out",
                 (out / "decoder").string()}),
           decoder},
          // Half of its frames read through the final tokenizer, as gaia eval reads generated frames.
          {"probe-scene", with({"probe", "train", "scene", synth, "--steps", std::to_string(st->probe_scene), "--tokenizer",
                                tok, "--decoded-share", "0.5", "--out", (out / "probe-scene").string()}),
           out / "probe-scene" / "probe-scene.safetensors"},
          {"probe-dynamics",
           with({"probe", "train", "dynamics", synth, "--steps", std::to_string(st->probe_dynamics), "--out", (out / "probe-dynamics").string()}),
           out / "probe-dynamics" / "probe-dynamics.safetensors"},
      };
      // The decoder alone, encoder and codebook frozen, grown by two full-resolution and two token-grid blocks and
      // averaged over its steps: the blocks start as identities and learn what the fine-tuned decoder
      // still misses, and every frame keeps the codes of tokenizer-ft. (The config defaults stay 0 so that weights
      // saved before these keys existed load as saved.)
      if (st->refine > 0)
        stages.insert(stages.begin() + 3,
                      {"tokenizer-refine",
                       no_gan_run(tok_ft, st->refine, "tokenizer-refine",
                                  {"--decoder-only", "--set", "tokenizer.refine_blocks=2", "--set", "tokenizer.token_blocks=2",
                                   "--set", "tokenizer.ema_decay=0.999"}),
                       tok});
      // The counterfactual replays are added to the tokens after the world model's first phase, which then
      // fine-tunes on both at half its rate, more often action-conditioned (0.6 / 0.25 / 0.15), its text-only and
      // unconditional predictions held to the first phase's (--distill-from), so the replays cost nothing of the
      // text conditioning.
      if (st->world_cf > 0) {
        const std::string first = first_phase.string();
        const auto at = std::find_if(stages.begin(), stages.end(), [](const Stage& x) { return x.name == "world"; }) + 1;
        std::vector<Stage> cf_stages = counterfactuals(out, synth, tok, tokens);
        // Each round starts from the round before; every round is held to the first phase, not to the round before.
        for (int round = 1; round <= st->world_cf_rounds; ++round) {
          const std::string init = round == 1 ? first : (cf_dir(round - 1) / "world.safetensors").string();
          cf_stages.push_back({cf_dir(round).filename().string(),
                               with({"world", "train", tokens, "--init", init, "--distill-from", first, "--steps",
                                     std::to_string(st->world_cf), "--set", "world.lr=1.5e-4", "--set",
                                     "world.warmup_steps=50", "--set", "world.p_action=0.6", "--set", "world.p_text=0.25",
                                     "--set", "world.p_uncond=0.15", "--out", cf_dir(round).string()}),
                               cf_dir(round) / "world.safetensors"});
        }
        stages.insert(at, cf_stages.begin(), cf_stages.end());
      }
      const auto drives = more_drives(synth, *episodes);
      stages.insert(stages.begin() + 1, drives.begin(), drives.end());
      if (!*skip_eval) {
        stages.push_back({"world-eval", with({"world", "eval", tokens, "--world", world, "--out", (out / "world-eval").string()}),
                          out / "world-eval" / "eval.json"});
        stages.push_back({"decoder-eval",
                          with({"decoder", "eval", synth, "--tokenizer", tok, "--decoder", decoder, "--steps", "50,20,10",
                                "--out", (out / "decoder-eval").string()}),
                          out / "decoder-eval" / "eval.json"});
        stages.push_back({"eval",
                          with({"eval", tokens, synth, "--world", world, "--tokenizer", tok,
                                "--dynamics-probe", (out / "probe-dynamics" / "probe-dynamics.safetensors").string(),
                                "--scene-probe", (out / "probe-scene" / "probe-scene.safetensors").string(),
                                "--world-eval", (out / "world-eval").string(), "--metrics",
                                "world=" + (out / "world" / "metrics.jsonl").string(),
                                "decoder=" + (out / "decoder" / "metrics.jsonl").string(),
                                "tokenizer=" + (out / "tokenizer" / "metrics.jsonl").string(), "--out",
                                (out / "eval").string()}),
                          out / "eval" / "report.html"});
      }
      if (!ship.empty()) {
        const std::vector<std::pair<std::string, std::string>> files = {
            {tok, "tokenizer.safetensors"}, {world, "world.safetensors"}, {decoder, "decoder.safetensors"},
            {(out / "probe-scene" / "probe-scene.safetensors").string(), "probe-scene.safetensors"},
            {(out / "probe-dynamics" / "probe-dynamics.safetensors").string(), "probe-dynamics.safetensors"}};
        for (auto& [file, to] : files)
          stages.push_back({"ship " + to, {"convert", file, "--half", "--out", (fs::path(ship) / to).string()},
                            fs::path(ship) / to});
      }
      return stages;
    };

    std::vector<Stage> stages;
    if (user_data->empty()) {
      stages = procedural(out, *ship);
    } else {
      const bool clips = !manifest->empty();
      const std::string data = (out / "data").string(), tk = (out / "tokenizer" / "tokenizer.safetensors").string();
      const std::string tokens = (out / "tokens").string(), trained_world = (out / "world" / "world.safetensors").string();
      const std::string world = (out / "world-calibrated" / "world.safetensors").string();
      const std::string decoder = (out / "decoder" / "decoder.safetensors").string();
      fs::path base = *from;  // the models this run fine-tunes ("" = none: from nothing)
      if (clips && base.empty()) {
        // The release from nothing: the procedural recipe first, its models shipped into OUT/procedural/release,
        // then the fine-tune on the clips and procedural drives together.
        auto first = procedural(out / "procedural", (out / "procedural" / "release").string());
        stages.insert(stages.end(), first.begin(), first.end());
        base = out / "procedural" / "release";
      }
      fs::path src = *user_data;
      if (clips) {
        src = out / "real";
        stages.push_back({"ingest", with({"ingest", *user_data, "--manifest", *manifest, "--motion", "video", "--out", src.string()}),
                          src / ".complete", true});
      }
      stages.push_back({"data", {"(link the episodes of " + src.string() + " into " + data + ")"}, out / "data" / ".complete",
                        true, [src, data] { link_dataset(src, data); }});
      // Procedural drives mixed in: --synth lane-keeping ones (with a manifest: the recipe's --episodes, then its
      // wandering and swerving drives).
      const int lane = clips && !synth_given() ? *episodes : *synth_mix;
      if (lane > 0)
        stages.push_back({"data-synth", with({"synth", "--episodes", std::to_string(lane), "--seconds",
                                              fmt::format("{}", *seconds), "--seed", "1", "--out", data}),
                          out / "data" / ".complete-synth", true});
      if (clips) {
        const auto drives = more_drives(data, lane);
        stages.insert(stages.end(), drives.begin(), drives.end());
        // Clips held out by source and place (no held-out clip shares a drive with a training clip), every
        // condition on both sides where the clips allow; procedural drives as the default split holds them out.
        stages.push_back({"split", with({"data", "split", data, "--hold-out-by", "source_repo,place"}), out / "data" / "split.json"});
      }
      const std::string tsteps = std::to_string(st->tokenizer > 0 ? st->tokenizer : c.tokenizer.steps);
      if (base.empty()) {
        stages.push_back({"tokenizer", with({"tokenizer", "train", data, "--steps", tsteps, "--out", (out / "tokenizer").string()}), tk});
      } else {
        // The decoder alone, without the GAN term: every frame keeps the codes the world model and the video
        // decoder were trained on, so they fit from the first step. Half of each batch real when procedural drives
        // are mixed in.
        // --new-codes: encoder and codebook too, at twice the rate, so the codes move to the new frames.
        std::vector<std::string> a{"tokenizer", "train", data, "--init", (base / "tokenizer.safetensors").string(),
                                   "--steps", tsteps, "--set", "tokenizer.ema_decay=0.999", "--set",
                                   "tokenizer.disc_start=1000000", "--set", "tokenizer.warmup_steps=50"};
        if (*new_codes)  // a quarter of each batch darkened: codes for nights darker than the drives (augment.h)
          a.insert(a.end(), {"--set", "tokenizer.lr=2e-4", "--set", "tokenizer.final_lr=2e-5", "--set",
                             "tokenizer.augment_dark=0.25"});
        else
          a.insert(a.end(), {"--decoder-only", "--set", "tokenizer.lr=1e-4", "--set", "tokenizer.final_lr=1e-5"});
        if (lane > 0) a.insert(a.end(), {"--set", "data.balance_tokenizer=[footage]", "--set", "data.balance_exponent=1"});
        a.insert(a.end(), {"--out", (out / "tokenizer").string()});
        stages.push_back({"tokenizer", with(a), tk});
      }
      stages.push_back({"tokens", with({"tokenize", data, "--tokenizer", tk, "--mirror", "--out", tokens}),
                        out / "tokens" / "dataset.json"});
      if (clips && st->world_cf > 0) {
        const auto cf = counterfactuals(out, data, tk, tokens);
        stages.insert(stages.end(), cf.begin(), cf.end());
      }
      std::vector<std::string> wa{"world", "train", tokens, "--steps", std::to_string(st->world)};
      if (!base.empty()) {
        const std::string w = (base / "world.safetensors").string();
        wa.insert(wa.end(), {"--init", w, "--set", "world.lr=2e-4", "--set", "world.warmup_steps=50"});
        // Procedural windows held to the model fine-tuned, which knows that world; real ones learn freely. Not with
        // --new-codes: that model predicts the old codes, and most token ids name another code after the fine-tune.
        if (lane > 0 && !*new_codes) wa.insert(wa.end(), {"--distill-from", w, "--distill-procedural-only"});
      }
      if (lane > 0)  // footage a balancing feature: real windows drawn as often as sqrt of their share allows
        wa.insert(wa.end(), {"--set", "data.balance_world=[footage,latitude,longitude,weather,steering,speed]"});
      wa.insert(wa.end(), {"--out", (out / "world").string()});
      stages.push_back({"world", with(wa), trained_world});
      std::vector<std::string> ca{"world", "calibrate", tokens, "--world", trained_world};
      if (lane > 0) ca.insert(ca.end(), {"--without-meta", "synth_wander", "--without-meta", "replay_of"});
      ca.insert(ca.end(), {"--out", world});
      stages.push_back({"world-calibrate", with(ca), world});
      // From --from weights the decoder needs only what the codes changed: nothing while they stay (its weights are
      // kept), a short fine-tune when they moved.
      const int dsteps = base.empty() || decoder_opt->count() > 0 ? st->decoder : *new_codes ? 300 : 0;
      if (dsteps > 0) {
        std::vector<std::string> da{"decoder", "train", data, "--tokenizer", tk, "--steps", std::to_string(dsteps)};
        if (!base.empty()) da.insert(da.end(), {"--init", (base / "decoder.safetensors").string()});
        da.insert(da.end(), {"--out", (out / "decoder").string()});
        stages.push_back({"decoder", with(da), decoder});
      } else {
        const fs::path kept = base / "decoder.safetensors";
        stages.push_back({"decoder", {"(keep " + kept.string() + " as " + decoder + ")"}, decoder, false, [kept, decoder] {
                            fs::create_directories(fs::path(decoder).parent_path());
                            fs::copy_file(kept, decoder + ".part", fs::copy_options::overwrite_existing);
                            fs::rename(decoder + ".part", decoder);
                          }});
      }
      const std::string realism = (out / "probe-realism" / "probe-realism.safetensors").string();
      // Real or procedural: what reads whether futures of a real prompt stay real (where the drives are recorded).
      bool recorded = clips;
      if (!clips) {
        data::Dataset mine(src);
        for (size_t e = 0; e < mine.size() && !recorded; ++e) recorded = !mine.meta(e).is_procedural();
      }
      if (lane > 0 && recorded)
        // Half of each batch read through the tokenizer, as gaia eval reads generated frames: decoding alone must
        // not read as procedural.
        stages.push_back({"probe-realism", with({"probe", "train", "realism", data, "--steps", std::to_string(st->probe_realism),
                                                 "--tokenizer", tk, "--decoded-share", "0.5",
                                                 "--out", (out / "probe-realism").string()}), realism});
      // The dynamics probe learns the recorded drives' estimated motion beside the procedural world's, each example
      // also in mirror image: one probe trained on procedural frames alone reads real roads as turning left.
      const std::string dynamics = (out / "probe-dynamics" / "probe-dynamics.safetensors").string();
      if (lane > 0 && recorded)
        stages.push_back({"probe-dynamics", with({"probe", "train", "dynamics", data, "--steps",
                                                  std::to_string(st->probe_dynamics), "--mirror", "--out",
                                                  (out / "probe-dynamics").string()}), dynamics});
      if (!*skip_eval)
        stages.push_back({"world-eval", with({"world", "eval", tokens, "--world", world, "--out", (out / "world-eval").string()}),
                          out / "world-eval" / "eval.json"});
      if (!ship->empty()) {
        std::vector<std::pair<std::string, std::string>> files = {
            {tk, "tokenizer.safetensors"}, {world, "world.safetensors"}, {decoder, "decoder.safetensors"}};
        if (lane > 0 && recorded) {
          files.push_back({realism, "probe-realism.safetensors"});
          files.push_back({dynamics, "probe-dynamics.safetensors"});
        }
        for (auto& [file, to] : files)
          stages.push_back({"ship " + to, {"convert", file, "--half", "--out", (fs::path(*ship) / to).string()},
                            fs::path(*ship) / to});
      }
    }
    fs::create_directories(out);
    nlohmann::json log = nlohmann::json::array();
    for (size_t i = 0; i < stages.size(); ++i) {
      const auto& s = stages[i];
      const std::string line = joined(s.args);
      if (fs::exists(s.done)) {
        std::printf("[%zu/%zu] %s: done (%s exists), skipped\n", i + 1, stages.size(), s.name.c_str(), s.done.c_str());
        log.push_back({{"stage", s.name}, {"command", line}, {"skipped", true}});
        continue;
      }
      std::printf("[%zu/%zu] %s: %s\n", i + 1, stages.size(), s.name.c_str(), line.c_str());
      const auto t0 = std::chrono::steady_clock::now();
      int rc = 0;
      if (s.in_process) s.in_process();
      else rc = run_gaia_child(s.args);
      const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (rc != 0) fail("train-all: stage '{}' failed (exit {}); fix it and run the same command again to resume", s.name, rc);
      if (s.write_done) write_file_atomic(s.done, "");
      std::printf("[%zu/%zu] %s: finished in %.1f min\n", i + 1, stages.size(), s.name.c_str(), secs / 60);
      log.push_back({{"stage", s.name}, {"command", line}, {"seconds", secs}});
      write_file_atomic(out / "train-all.json", log.dump(2) + "\n");
    }
    write_file_atomic(out / "train-all.json", log.dump(2) + "\n");
    std::printf("train-all: every stage done in %s (commands and times: %s)\n", out.c_str(),
                (out / "train-all.json").c_str());
  });
}

}  // namespace gaia::app
