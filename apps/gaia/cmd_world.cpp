// gaia world train|eval|calibrate: the world model of §2.3 on a token dataset (gaia tokenize, or other tokenizers'
// token files).
#include <cstdio>

#include <nlohmann/json.hpp>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/calibrate.h"
#include "gaia/world/evaluate.h"
#include "gaia/world/world_eval.h"
#include "gaia/world/io.h"
#include "gaia/world/text_embeddings.h"
#include "gaia/world/token_file.h"
#include "gaia/world/trainer.h"

namespace gaia::app {

namespace {

// --world's model on the run's device, with its own config: its keys cannot be --set here (the weights fix them).
world::WorldModel load_world_for(const SharedFlags& flags, const Config& run, const std::string& weights,
                                 world::WorldInfo* info) {
  auto model = world::load_world(weights, parse_device(run.run.device), info);
  apply_sampling_sets(flags, "world", {}, weights, info->config);
  return model;
}

void check_tokens(const world::TokenDataset& ds, const world::WorldInfo& info, const std::string& tokens) {
  if (ds.tokens_per_step() != info.n())
    fail("{}: {} tokens per frame, the world model was trained on {}", tokens, ds.tokens_per_step(), info.n());
}

}  // namespace

void register_world(CLI::App& app) {
  auto* world = app.add_subcommand("world", "world model (§2.3): train, eval, calibrate");
  world->require_subcommand(1);

  {
    auto* cmd = world->add_subcommand("train", "train the world model on a token dataset (resumes from OUT/checkpoint)");
    auto flags = std::make_shared<SharedFlags>();
    auto o = std::make_shared<world::WorldTrainOptions>();
    auto tokens = std::make_shared<std::string>();
    auto format = std::make_shared<TokenFormatFlags>();
    cmd->add_option("TOKENS", *tokens, "token dataset (gaia tokenize), or another tokenizer's token file or directory "
                    "of them (.npy / .safetensors; see --grid)")->required();
    add_token_format_flags(cmd, format.get());
    cmd->add_option("--steps", o->steps, "total steps (default: config world.steps)")->check(number_in({1, 1e9}));
    cmd->add_option("--val-every", o->val_every,
                    "steps between validations (0 = only at the end; default: 250, or two passes over a small "
                    "training set where that is sooner)");
    cmd->add_option("--stop-after", o->stop_after, "stop after this many steps of this run (checkpointed)")->check(number_in({1, 1e9}));
    cmd->add_option("--init", o->init,
                    "start from these world model weights (fine-tuning; ignored when resuming; their copy bias is not "
                    "carried over: each validation fits it again)");
    cmd->add_flag("--no-calibrate", [o](int64_t) { o->calibrate = false; },
                  "do not fit the copy bias (world.copy_bias, world.copy_bias_run) at each validation (on the held-out "
                  "windows, each half scored with the other half's fit) nor write it with the weights: the paper's "
                  "model, bias 0 (or the config's)");
    cmd->add_option("--train-only", o->train_only,
                    "train only the parameters whose names start with these (comma-separated, e.g. "
                    "speed_mlp,curvature_mlp); the rest stay as --init gave them")
        ->delimiter(',');
    cmd->add_option("--distill-from", o->distill_from,
                    "keep the text-conditioned and unconditional predictions of these weights (usually --init's): every "
                    "example that is not action-conditioned adds a KL term to them (learning without forgetting)");
    cmd->add_option("--distill-weight", o->distill_weight, "weight of that KL term");
    cmd->add_flag("--distill-other-text", o->distill_other_text,
                  "with --distill-from: also keep its text-conditioned predictions when half the batch is given other "
                  "examples' captions (prompts that contradict the frames, as text prompting does); ~1.5x step time");
    cmd->add_flag("--distill-procedural-only", o->distill_procedural_only,
                  "with --distill-from: hold only windows of procedural drives (gaia synth) to it: a teacher that has "
                  "never seen recorded footage keeps the procedural world and teaches nothing about real frames (nor "
                  "about drives whose conditions change, synth --change-at)");
    auto t5 = std::make_shared<std::string>();
    add_weights_flag(cmd, Weights::T5, t5.get(),
                     "text as its embeddings (§2.1): the captions are embedded first, once (gaia text embed), "
                     "instead of the built-in words");
    auto encoder = std::make_shared<std::string>();
    cmd->add_option("--text-encoder", *encoder,
                    "what reads the captions (§2.1): words (the built-in vocabulary), t5 (with --t5 DIR) or "
                    "precomputed (the dataset's embeddings, from any encoder); default: --init's, else the "
                    "dataset's embeddings where it has them, else words")
        ->check(CLI::IsMember({"words", "t5", "precomputed"}));
    cmd->add_flag("--fresh-text", o->fresh_text,
                  "with --init: learn the text path (word embedding, text projection) afresh, with this dataset's "
                  "words; implied when --text-encoder differs from what --init read");
    add_shared_flags(cmd, flags.get(), "run directory (checkpoint/, world.safetensors, metrics.jsonl)");
    auto par = std::make_shared<ParallelFlags>();
    add_parallel_flags(cmd, par.get());
    cmd->callback([=] {
      Config c = resolve_config(*flags);
      if (flags->out.empty()) fail("gaia world train: --out RUN_DIR is required");
      if (*encoder == "t5" && t5->empty()) fail("--text-encoder t5 needs --t5 DIR (a T5 encoder's folder)");
      if (!t5->empty() && !encoder->empty() && *encoder != "t5")
        fail("--t5 {} contradicts --text-encoder {}", *t5, *encoder);
      if (o->fresh_text && o->init.empty()) fail("--fresh-text needs --init (a fine-tune's text path)");
      // Before any rank starts, so they find the embeddings there; ranks of a job (several machines) check only.
      if (!t5->empty()) {
        // m as the model reads it: a fine-tune's is its --init model's
        const int64_t m = o->init.empty() ? c.world.text_tokens : world::read_world_info(o->init).config.world.text_tokens;
        if (!std::getenv("WORLD_SIZE")) embed_dataset_captions(*tokens, *t5, m, parse_device(c.run.device));
        else if (!fs::exists(fs::path(*tokens) / world::kTextEmbInfoFile))
          fail("{}: no text embeddings yet: run gaia text embed {} --t5 {} before the job", *tokens, *tokens, *t5);
      }
      if (launch_local_ranks(*par)) return;
      auto dist = join_job(*par, c);
      world::WorldTrainOptions opt = *o;
      using Text = world::WorldTrainOptions::Text;
      opt.text = *encoder == "words" ? Text::Words : (!t5->empty() || *encoder == "precomputed") ? Text::Embeddings : Text::Auto;
      opt.parallel = parallel_of(*par, dist.get());
      opt.tokens = *tokens;
      opt.format = token_format(*format, c, false);
      opt.out = flags->out;
      std::unique_ptr<ProgressBar> bar;
      auto r = world::train_world(
          c, opt,
          [&](const world::WorldStepLog& l) {
            if (!bar) bar = std::make_unique<ProgressBar>(l.total, "world", true, l.step);  // a resumed run starts mid-way
            std::string info = fmt::format("loss {:.3f} {:.0f} tok/s", l.loss, l.tokens_per_s);
            if (l.distill >= 0) info += fmt::format(" kl {:.4f}", l.distill);
            if (l.distill_other >= 0) info += fmt::format(" / {:.4f}", l.distill_other);
            if (l.validation && !l.val.empty()) {
              info += fmt::format(" | val {:.3f} bits/token", l.val.value("bits_per_token", 0.0));
              if (l.val.contains("copy_bias"))  // calibrated in the recipe: the bias and what it gained
                info += fmt::format(" (copy bias {:.2f}{:+.2f} in runs; {:.3f} without)",
                                    l.val["copy_bias"].get<double>(), l.val.value("copy_bias_run", 0.0),
                                    l.val["bits_per_token_uncalibrated"].get<double>());
            }
            bar->update(l.step, info);
          },
          [](const std::string& n) { std::fprintf(stderr, "world: %s\n", n.c_str()); });
      if (bar) bar->finish();
      if (!dist->is_main()) return;
      const int total = opt.steps > 0 ? opt.steps : c.world.steps;
      std::printf("world: step %d%s; last validation %s\n", r.final_step,
                  r.final_step >= total ? " (done)" : " (checkpointed)", r.last_val.dump().c_str());
      if (r.best_step >= 0)
        std::printf("world: best validation %.4f bits/token at step %d -> %s\n", r.best_bits, r.best_step,
                    (fs::path(flags->out) / "best.safetensors").c_str());
    });
  }

  {
    auto* cmd = world->add_subcommand(
        "eval", "validation cross-entropy and bits/token against xz and zstd, shuffled conditioning, Fig. 5 plot");
    auto flags = std::make_shared<SharedFlags>();
    auto tokens = std::make_shared<std::string>(), weights = std::make_shared<std::string>();
    auto max_windows = std::make_shared<size_t>(256);
    auto sweep = std::make_shared<std::vector<int>>();
    auto sweep_windows = std::make_shared<size_t>(64);
    auto format = std::make_shared<TokenFormatFlags>();
    cmd->add_option("TOKENS", *tokens, "token dataset or token files (their validation episodes are scored)")->required();
    add_token_format_flags(cmd, format.get());
    add_weights_flag(cmd, Weights::World, weights.get())->required();
    cmd->add_option("--max-windows", *max_windows, "held-out windows of T steps to score");
    cmd->add_option("--top-k-sweep", *sweep,
                    "Fig. 5 strategies: k values for top-k sampling of each window's last frame, scored like real "
                    "tokens (1 = argmax, 0 = the whole distribution; default: 1, world.top_k, 0)")
        ->delimiter(',');
    cmd->add_option("--sweep-windows", *sweep_windows, "held-out windows whose last frame each strategy generates");
    auto footage = std::make_shared<std::string>();
    add_footage_flag(cmd, "--footage", footage.get(), "which held-out episodes are scored");
    add_shared_flags(cmd, flags.get(), "output directory (eval.json, perplexity_by_position.svg)");
    cmd->callback([=] {
      Config run = resolve_config(*flags);
      apply_threads(run);
      world::WorldInfo info;
      auto model = load_world_for(*flags, run, *weights, &info);
      world::TokenDataset ds(*tokens, token_format(*format, run, false, &info));
      check_tokens(ds, info, *tokens);
      world::WorldEvalOptions eo;
      eo.max_windows = *max_windows;
      eo.top_k_sweep = *sweep;
      eo.sweep_windows = *sweep_windows;
      eo.footage = world::parse_footage(*footage);
      eo.name = *tokens;
      eo.weights = *weights;
      // --precision: the products of every scoring pass in bf16 (where this device does it), as sampling runs them.
      const auto dev = model->token_embedding->weight.device();
      const Precision precision = run_precision(run, dev, "world eval");
      std::unique_ptr<ProgressBar> bar;
      nlohmann::json j;
      {
        Autocast autocast(precision, dev);
        j = world::evaluate_world(model, info, ds, eo, [&](int done, int total) {
          if (!bar) bar = std::make_unique<ProgressBar>(total, "world eval");
          bar->update(done);
        });
      }
      j["precision"] = to_string(precision);
      if (bar) bar->finish();
      std::printf("%s\n", j.dump(2).c_str());
      if (!flags->out.empty()) world::write_world_eval(j, flags->out);
    });
  }

  {
    auto* cmd = world->add_subcommand(
        "calibrate", "fit world.copy_bias and world.copy_bias_run (how likely a patch is to keep its code from one frame "
                     "to the next, on its own and after a patch that kept its code) by maximum likelihood on training "
                     "windows, and write the model with them");
    auto flags = std::make_shared<SharedFlags>();
    auto tokens = std::make_shared<std::string>(), weights = std::make_shared<std::string>();
    auto max_windows = std::make_shared<size_t>(256);
    auto format = std::make_shared<TokenFormatFlags>();
    cmd->add_option("TOKENS", *tokens, "token dataset or token files (their training episodes are used; all episodes "
                    "if none is held out)")->required();
    add_token_format_flags(cmd, format.get());
    add_weights_flag(cmd, Weights::World, weights.get())->required();
    cmd->add_option("--max-windows", *max_windows, "training windows of T steps, evenly spaced");
    auto without = std::make_shared<std::vector<std::string>>();
    cmd->add_option("--without-meta", *without,
                    "leave out episodes whose metadata has this key: calibrate on the kind of driving you will roll "
                    "out, e.g. synth_wander keeps gaia synth's lane-keeping drives (repeatable)");
    add_shared_flags(cmd, flags.get(), "output weights file (may be --world itself)", WithPrecision::kNo);
    cmd->callback([=] {
      Config run = resolve_config(*flags);
      apply_threads(run);
      if (flags->out.empty()) fail("gaia world calibrate: --out FILE is required");
      if (*max_windows < 1) fail("--max-windows must be >= 1");
      world::WorldInfo info;
      auto model = load_world_for(*flags, run, *weights, &info);
      world::TokenDataset ds(*tokens, token_format(*format, run, false, &info));
      check_tokens(ds, info, *tokens);
      auto ids = ds.split(0.1, info.config.run.seed).train;
      if (ids.empty()) ids = ds.ids();
      std::vector<size_t> eps;
      for (size_t e : ds.indices(ids))
        if (!ds.meta(e).has_any_extra(*without)) eps.push_back(e);
      auto windows = world::validation_windows(ds, eps, info.config.world.context_steps, *max_windows);
      if (windows.empty())
        fail("{}: no training window of {} steps{}", *tokens, info.config.world.context_steps,
             without->empty() ? "" : " in the episodes without " + fmt::format("{}", fmt::join(*without, ", ")));
      const auto text = world::text_source(info, ds);
      ProgressBar bar(int64_t(windows.size()), "calibrate");
      auto c = world::calibrate_copy_bias(model, ds, windows, text, world::ConditioningMix::from(info.config.world),
                                          info.config.world.batch_size, [&](int64_t d, int64_t) { bar.update(d); });
      bar.finish();
      if (!c.fitted)
        fail("{}: {} of the {} tokens with a previous frame in view were copied from it: the copy bias has no finite "
             "optimum", *tokens, c.copy_rate > 0 ? "all" : "none", c.tokens);
      const double was = info.config.world.copy_bias, was_run = info.config.world.copy_bias_run;
      info.config.world.copy_bias = model->cfg.copy_bias = c.bias;
      info.config.world.copy_bias_run = model->cfg.copy_bias_run = c.run;
      if (fs::path(flags->out).has_parent_path()) fs::create_directories(fs::path(flags->out).parent_path());
      world::save_world(model, info, flags->out);
      std::printf("%s: world.copy_bias %.4f (was %.4f), world.copy_bias_run %.4f (was %.4f) from %zu windows, %lld "
                  "tokens: real copy rate %.4f, the model gave it %.4f -> %.4f; cross-entropy %.4f -> %.4f nats\n",
                  flags->out.c_str(), c.bias, was, c.run, was_run, windows.size(), (long long)c.tokens, c.copy_rate,
                  c.predicted_before, c.predicted_after, c.nats_before, c.nats_after);
    });
  }
}

}  // namespace gaia::app
