// gaia probe train|eval|read: the evaluation probes (dynamics: speed and curvature from K >= 2 frames one world-model
// step apart; scene: weather, time of day, light state, lead vehicle close, trained on procedural-world data with
// ground-truth labels; realism: real footage or procedural, trained on both).
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/data/geofence.h"
#include "gaia/data/video_io.h"
#include "gaia/probe/trainer.h"
#include "gaia/tokenizer/io.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::app {

void register_probe(CLI::App& app) {
  auto* probe = app.add_subcommand("probe", "evaluation probes: train, eval, read (dynamics | scene | realism)");
  probe->require_subcommand(1);
  {
    auto* cmd = probe->add_subcommand("train", "train a probe on a gaia synth dataset, or realism on real and "
                                      "procedural episodes (resumes from OUT/checkpoint)");
    auto flags = std::make_shared<SharedFlags>();
    auto o = std::make_shared<probe::ProbeTrainOptions>();
    auto kind = std::make_shared<std::string>(), dataset = std::make_shared<std::string>();
    cmd->add_option("KIND", *kind, "dynamics | scene | realism")->required();
    cmd->add_option("DATASET", *dataset, "episode dataset with labels (gaia synth); realism: real (gaia ingest) and "
                    "procedural (gaia synth) episodes in one dataset, half of each batch from each")->required();
    cmd->add_option("--steps", o->steps, "training steps")->check(number_in({1, 1e9}));
    cmd->add_option("--batch-size", o->batch, "examples per step");
    cmd->add_option("--batch", o->batch, "old spelling of --batch-size")->group("");
    cmd->add_option("--frames", o->frames,
                    "dynamics: frames one example reads, one world-model step apart (default 4: gentle steering barely "
                    "shows in 2; `gaia eval` then needs at least 3 generated frames)");
    cmd->add_option("--val-every", o->val_every, "steps between validations (0 = only at the end)");
    cmd->add_option("--stop-after", o->stop_after, "stop after this many steps of this run (checkpointed)")->check(number_in({1, 1e9}));
    auto* through = add_weights_flag(cmd, Weights::Tokenizer, &o->tokenizer,
                                     "a share of the training frames is read through it (encoded and decoded), as "
                                     "`gaia eval` reads generated frames; validation then also scores decoded "
                                     "held-out frames");
    cmd->add_option("--decoded-share", o->decoded_share, "with --tokenizer: the share of each batch decoded (0..1)")
        ->needs(through);
    cmd->add_flag("--mirror", o->mirror,
                  "dynamics: half of each batch in mirror image with its curvature negated, so that the probe reads "
                  "left and right alike");
    add_shared_flags(cmd, flags.get(), "run directory (checkpoint/, probe-KIND.safetensors, metrics.jsonl)",
                     WithPrecision::kNo);
    cmd->callback([=] {
      Config c = resolve_config(*flags);
      apply_threads(c);
      if (flags->out.empty()) fail("gaia probe train: --out RUN_DIR is required");
      probe::ProbeTrainOptions opt = *o;
      opt.kind = probe::parse_kind(*kind);
      opt.dataset = *dataset;
      opt.out = flags->out;
      if (opt.steps < 1 || opt.batch < 1) fail("gaia probe train: --steps and --batch-size must be >= 1");
      if (opt.frames < 0) fail("gaia probe train: --frames must be >= 1, got {}", opt.frames);
      if (opt.mirror && opt.kind != probe::ProbeKind::kDynamics)
        fail("gaia probe train: --mirror is for the dynamics probe (the {} probe's labels have no side)", *kind);
      if (!(opt.decoded_share >= 0 && opt.decoded_share <= 1))
        fail("gaia probe train: --decoded-share must be in [0, 1], got {}", opt.decoded_share);
      std::unique_ptr<ProgressBar> bar;
      auto r = probe::train_probe(
          c, opt,
          [&](int step, int total, double loss, const nlohmann::json&) {
            if (!bar) bar = std::make_unique<ProgressBar>(total, "probe " + *kind, true, step);
            bar->update(step, fmt::format("loss {:.4f}", loss));
          },
          [](const std::string& n) { std::fprintf(stderr, "probe: %s\n", n.c_str()); });
      if (bar) bar->finish();
      std::printf("probe %s: step %d%s; held-out %s\n", kind->c_str(), r.final_step,
                  r.weights.empty() ? " (checkpointed)" : (" -> " + r.weights.string()).c_str(), r.last_val.dump().c_str());
    });
  }
  {
    auto* cmd = probe->add_subcommand("eval", "score a probe on the held-out episodes of a labelled dataset (realism: "
                                      "half real, half procedural frames)");
    auto flags = std::make_shared<SharedFlags>();
    auto weights = std::make_shared<std::string>(), dataset = std::make_shared<std::string>();
    auto old_second = std::make_shared<std::string>();
    auto n = std::make_shared<int>(512);
    cmd->add_option("DATASET", *dataset, "episode dataset with labels")->required();
    // The old spelling `probe eval WEIGHTS DATASET`: a second positional, hidden.
    auto* old_form = cmd->add_option("OLD_DATASET", *old_second, "old spelling: WEIGHTS DATASET")->group("");
    add_weights_flag(cmd, Weights::Probe, weights.get());
    auto tok_path = std::make_shared<std::string>();
    cmd->add_option("--examples", *n, "held-out examples (evenly spaced)")->check(number_in({1, 1e9}));
    add_weights_flag(cmd, Weights::Tokenizer, tok_path.get(),
                     "also score the frames read through it (encoded and decoded), as `gaia eval` reads generated "
                     "frames (key \"decoded\")");
    add_shared_flags(cmd, flags.get(), "output directory (probe_eval.json, WithPrecision::kNo); default: print only");
    cmd->callback([=] {
      if (old_form->count() > 0) {
        if (!weights->empty()) fail("gaia probe eval: give the weights once: DATASET --probe WEIGHTS");
        std::fprintf(stderr, "gaia: note: `probe eval WEIGHTS DATASET` is an old spelling; use DATASET --probe WEIGHTS\n");
        *weights = *dataset;
        *dataset = *old_second;
      }
      if (weights->empty()) fail("gaia probe eval: --probe WEIGHTS is required");
      Config c = resolve_config(*flags);
      apply_threads(c);
      auto dev = parse_device(c.run.device);
      auto net = probe::load_probe(*weights, dev);
      data::Dataset ds(*dataset);
      const probe::Span span = probe::span_of(net, c);
      auto set = net->kind == probe::ProbeKind::kRealism
                     ? probe::footage_balanced_set(ds, data::held_out_ids(ds, c.run.seed), std::max(1, *n))
                     : data::held_out_frames(ds, c.run.seed, span.reach(), std::max(1, *n));
      if (net->kind == probe::ProbeKind::kDynamics) probe::keep_with_signals(set, span);
      if (set.frames.empty())
        fail("{}: no held-out episode is long enough for this probe ({} frames, {} native frames from the first to "
             "the last)", *dataset, span.frames, span.reach() + 1);
      const auto y = probe::targets(net->kind, set.episodes, set.frames, span);
      auto j = probe::score_by_footage(net->kind, probe::predict(net, set, span, dev), y, set);
      if (!tok_path->empty()) {
        const auto& e = set.frames[0];
        auto tok = probe::load_through(*tok_path, set.episodes.at(e.episode)->frame_bgr(e.frame), *dataset, dev);
        j["decoded"] = probe::score_by_footage(net->kind, probe::predict(net, set, span, dev, {&tok, dev}), y, set);
      }
      j["frames"] = net->frames;
      if (!flags->out.empty()) {
        fs::create_directories(flags->out);
        write_file_atomic(fs::path(flags->out) / "probe_eval.json", j.dump(2) + "\n");
      }
      std::printf("%s\n", j.dump(2).c_str());
    });
  }
  {
    auto* cmd = probe->add_subcommand("read", "what a one-frame probe (realism, scene) reads in a video or in the "
                                      "generated frames of a rollout");
    auto flags = std::make_shared<SharedFlags>();
    auto src = std::make_shared<std::string>(), weights = std::make_shared<std::string>(),
         tok_path = std::make_shared<std::string>();
    auto with_prompt = std::make_shared<bool>(false);
    cmd->add_option("SOURCE", *src, "video file, or rollout.safetensors from gaia generate (needs --tokenizer)")->required();
    add_weights_flag(cmd, Weights::Probe, weights.get())->required();
    add_weights_flag(cmd, Weights::Tokenizer, tok_path.get(), "decodes a rollout's tokens into frames");
    cmd->add_flag("--with-prompt", *with_prompt, "rollout: also read the prompt frames (default: generated frames only)");
    add_shared_flags(cmd, flags.get(), "output directory (probe_read.json, WithPrecision::kNo); default: print only");
    cmd->callback([=] {
      Config c = resolve_config(*flags);
      apply_threads(c);
      auto dev = parse_device(c.run.device);
      auto net = probe::load_probe(*weights, dev);
      if (net->kind == probe::ProbeKind::kDynamics)
        fail("gaia probe read: {} is a dynamics probe, which reads frames one world-model step apart; gaia eval "
             "reads rollouts with it", *weights);
      std::vector<std::vector<cv::Mat>> futures;  // frames of each future (one for a video)
      if (fs::path(*src).extension() == ".safetensors") {
        if (tok_path->empty()) fail("gaia probe read: {} holds tokens; give --tokenizer to decode them", *src);
        int64_t prompt = 0;
        auto ids = read_tokens(*src, &prompt);  // [futures, frames, h, w]
        auto tok = tokenizer::load_tokenizer(*tok_path, dev);
        const int64_t first = *with_prompt ? 0 : std::min<int64_t>(prompt, ids.size(1) - 1);
        for (int64_t f = 0; f < ids.size(0); ++f)
          futures.push_back(tokenizer::decode_tokens(tok, ids[f].slice(0, first), dev));
      } else {
        data::VideoSource v(*src);
        data::VideoFrame f;
        std::vector<cv::Mat> frames;
        while (v.next(&f)) frames.push_back(data::resize_center_crop(f.bgr, c.data.height, c.data.width));
        if (frames.empty()) fail("{}: no frames", *src);
        futures.push_back(std::move(frames));
      }
      torch::NoGradGuard ng;
      nlohmann::json j = {{"probe", probe::to_string(net->kind)}, {"source", *src}};
      std::vector<torch::Tensor> outs;
      for (const auto& frames : futures) {
        std::vector<torch::Tensor> xs;
        for (size_t i = 0; i < frames.size(); i += 64) {
          std::vector<torch::Tensor> batch;
          for (size_t k = i; k < std::min(frames.size(), i + 64); ++k) batch.push_back(probe::probe_input({frames[k]}));
          xs.push_back(net->forward(torch::stack(batch).to(dev)).cpu());
        }
        outs.push_back(torch::cat(xs));
      }
      auto all = torch::cat(outs);
      j["frames"] = all.size(0);
      j["futures"] = outs.size();
      if (net->kind == probe::ProbeKind::kRealism) {
        j["read_as_real"] = (all.select(1, 0) > 0).to(torch::kFloat64).mean().item<double>();
        j["mean_p_real"] = torch::sigmoid(all.select(1, 0).to(torch::kFloat64)).mean().item<double>();
        std::vector<double> per;
        for (auto& o : outs) per.push_back((o.select(1, 0) > 0).to(torch::kFloat64).mean().item<double>());
        j["read_as_real_per_future"] = per;
      } else {
        auto heads = probe::split_scene_logits(all);
        const std::vector<std::string>* classes[3] = {&probe::weather_classes(), &probe::time_classes(),
                                                      &probe::light_classes()};
        const char* names[3] = {"weather", "time_of_day", "light_state"};
        for (int k = 0; k < 3; ++k) {
          auto arg = heads[size_t(k)].argmax(1);
          for (size_t ci = 0; ci < classes[k]->size(); ++ci)
            j[names[k]][(*classes[k])[ci]] = arg.eq(int64_t(ci)).to(torch::kFloat64).mean().item<double>();
        }
        j["lead_close"] = heads[3].argmax(1).to(torch::kFloat64).mean().item<double>();
      }
      if (!flags->out.empty()) {
        fs::create_directories(flags->out);
        write_file_atomic(fs::path(flags->out) / "probe_read.json", j.dump(2) + "\n");
      }
      std::printf("%s\n", j.dump(2).c_str());
    });
  }
}

}  // namespace gaia::app
