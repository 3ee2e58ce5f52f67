#include "gaia/world/trainer.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <fstream>

#include <torch/version.h>

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/sizing/sizing.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/checkpoint.h"
#include "gaia/train/optim.h"
#include "gaia/train/parallel_adamw.h"
#include "gaia/train/schedule.h"
#include "gaia/train/step_loop.h"
#include "gaia/world/calibrate.h"
#include "gaia/world/distill.h"
#include "gaia/world/evaluate.h"
#include "gaia/world/io.h"

namespace gaia::world {

namespace {

// The parameters a run trains (WorldTrainOptions::train_only); the others get requires_grad = false.
std::vector<torch::Tensor> trained_parameters(torch::nn::Module& model, const std::vector<std::string>& prefixes) {
  if (prefixes.empty()) return model.parameters();
  std::vector<torch::Tensor> out;
  std::vector<bool> used(prefixes.size(), false);
  for (auto& p : model.named_parameters()) {
    bool train = false;
    for (size_t i = 0; i < prefixes.size(); ++i)
      if (p.key().rfind(prefixes[i], 0) == 0) train = used[i] = true;
    p.value().set_requires_grad(train);
    if (train) out.push_back(p.value());
  }
  for (size_t i = 0; i < prefixes.size(); ++i)
    if (!used[i]) fail("--train-only: no world model parameter starts with '{}'", prefixes[i]);
  return out;
}

}  // namespace

WorldTrainResult train_world(const Config& config, const WorldTrainOptions& opt,
                             const std::function<void(const WorldStepLog&)>& on_step,
                             const std::function<void(const std::string&)>& on_note) {
  Config cfg = config;  // text embeddings of the dataset set world.text_tokens and world.text_dim (below)
  const auto& wc = cfg.world;
  const torch::Device dev = parse_device(cfg.run.device);
  WorldTrainResult result;
  train::Distributed& dist = opt.parallel.job();
  const bool main = dist.is_main();
  auto note = [&](const std::string& s) {
    result.notes.push_back(s);
    if (on_note && main) on_note(s);
  };
  const int accumulate = opt.parallel.accumulate;
  const int64_t micro = opt.parallel.micro_batch(wc.batch_size, "world.batch_size");
  // Weights, gradients and AdamW's two moments in float32, before any of it is allocated.
  sizing::check_memory(16.0 * double(sizing::world_params(cfg).total), "training this world model (world.*)");
  // One run per --out; a checkpoint a kill broke is put back (by rank 0, before any rank reads it).
  const auto run_dir = train::claim_run_dir(opt.out, dist, note);

  TokenDataset ds(opt.tokens, opt.format.for_training(opt.tokens, cfg.tokenizer.codebook_size));
  const int64_t T = wc.context_steps;
  auto split = ds.split(0.1, cfg.run.seed);
  auto train_eps = ds.indices(split.train);
  auto val_ids = split.held_out();
  auto val_eps = ds.indices(val_ids);
  auto train_windows = ds.windows(train_eps, T, 1);
  if (train_windows.empty())
    fail("{}: no training window of {} steps (world.context_steps); episodes are too short", opt.tokens.string(), T);
  WindowSampler sampler(ds, train_windows, ds.foreign() ? std::vector<std::string>{} : cfg.data.balance_world,
                        cfg.data.balance_exponent, cfg.data.balance_bins);
  int val_every = opt.val_every;
  if (val_every < 0) {  // two passes over the training steps, each step seeing batch_size windows of T steps
    const int64_t pass = int64_t(train_windows.size()) / std::max<int64_t>(1, int64_t(wc.batch_size) * T);
    val_every = int(std::clamp<int64_t>(2 * pass, 25, 250));
    if (val_every < 250)
      note(fmt::format("validating every {} steps: two passes over this small a training set", val_every));
  }
  // Fine-tuning keeps the --init model's vocabulary (on other data, word counts would renumber the words its
  // text embeddings were trained on), also when a fine-tuning run resumes.
  WorldModel init{nullptr};
  WorldInfo init_info;
  if (!opt.init.empty()) {
    init = load_world(opt.init, dev, &init_info);
    if (init_info.grid_h != ds.grid_h() || init_info.grid_w != ds.grid_w() || init_info.K != ds.codebook_size())
      fail("{}: a {}x{} token grid with K = {}, but {} has {}x{} with K = {}", opt.init.string(), init_info.grid_h,
           init_info.grid_w, init_info.K, opt.tokens.string(), ds.grid_h(), ds.grid_w(), ds.codebook_size());
  }
  // Text (§2.1): the dataset's precomputed embeddings where it has them (a fine-tune keeps its --init model's kind
  // of text unless told otherwise), else the built-in words.
  using Text = WorldTrainOptions::Text;
  const bool embeddings = opt.text == Text::Auto ? (init ? init_info.embeds_text() : ds.has_text_emb())
                                                 : opt.text == Text::Embeddings;
  if (embeddings && !ds.has_text_emb())
    fail("{}: no text embeddings (gaia text embed {} --t5 DIR){}", opt.tokens.string(), opt.tokens.string(),
         init ? fmt::format(", and {} was trained on embeddings of {}", opt.init.string(), init_info.text_encoder) : "");
  const std::string encoder = embeddings ? ds.text_emb().encoder : "";
  // Another text than --init's: its text path means nothing for this one and is learned afresh.
  const bool fresh_text = init && (opt.fresh_text || encoder != init_info.text_encoder);
  if (init && encoder != init_info.text_encoder && opt.text == Text::Auto && !opt.fresh_text)
    fail("{}: was trained on text embeddings of {}, but {} has embeddings of {} (--fresh-text learns its text path "
         "afresh for them)", opt.init.string(), init_info.text_encoder, opt.tokens.string(), encoder);
  text::Vocab vocab;
  if (embeddings) {
    const TextEmbInfo& e = ds.text_emb();
    if (init && e.m != init_info.config.world.text_tokens)
      fail("{}: reads m = {} text tokens per step, but {}'s embeddings have m = {} (gaia text embed {} --m {})",
           opt.init.string(), init_info.config.world.text_tokens, opt.tokens.string(), e.m, opt.tokens.string(),
           init_info.config.world.text_tokens);
    if (wc.text_tokens != e.m || wc.text_dim != e.dim)
      note(fmt::format("text: {}'s embeddings of {} set world.text_tokens = {} and world.text_dim = {} (config: {}, {})",
                       opt.tokens.string(), e.encoder, e.m, e.dim, wc.text_tokens, wc.text_dim));
    cfg.world.text_tokens = int(e.m);
    cfg.world.text_dim = int(e.dim);
  } else if (init && !fresh_text) {
    vocab = init_info.vocab;
    if (ds.has_text_emb() && opt.text == Text::Auto)
      note(fmt::format("text: {} was trained on words; the dataset's embeddings are not used", opt.init.string()));
  } else if (ds.has_captions()) {
    vocab = build_vocab(ds, train_eps, wc.text_vocab);
  }
  if (fresh_text)
    note(fmt::format("text: the text path (word_embedding, text_proj) starts afresh for {} ({} read {})",
                     embeddings ? "embeddings of " + encoder : std::string("the built-in words"), opt.init.string(),
                     init_info.embeds_text() ? "embeddings of " + init_info.text_encoder : std::string("words")));
  const TextSource text = embeddings ? TextSource::precomputed() : TextSource(ds.has_captions() ? &vocab : nullptr);
  if (!text.any()) note("no captions in the token dataset: text conditioning uses the null text only");
  auto val_windows = stream_windows(ds, val_eps, T, opt.val_windows);
  if (val_windows.empty()) note("no validation windows (no held-out episode of T steps): validation skipped");
  // Copy calibration at each validation (opt.calibrate), fitted on the held-out windows in two halves, each half
  // scored with the bias the other half gives: the bias fits frames the weights have not learned (fitted on
  // training windows, a model that memorises them asks for less copying the longer it trains, most of all on a
  // small dataset), and no score is of tokens its own bias was fitted to. One held-out window: training windows.
  std::vector<std::vector<Window>> calibration;
  if (opt.calibrate && val_windows.size() >= 2) {
    calibration.resize(2);
    for (size_t i = 0; i < val_windows.size(); ++i) calibration[i % 2].push_back(val_windows[i]);
  } else if (opt.calibrate && !val_windows.empty()) {
    calibration.push_back(stream_windows(ds, train_eps, T, opt.val_windows));
  }

  torch::manual_seed(cfg.run.seed);
  WorldModel model(wc, ds.tokens_per_step(), ds.codebook_size());
  model->to(dev);
  auto trained = trained_parameters(*model, opt.train_only);
  train::ParallelAdamW optim(trained, {wc.lr, wc.weight_decay, wc.beta1, wc.beta2}, opt.parallel);
  const int total = opt.steps > 0 ? opt.steps : wc.steps;
  train::WarmupCosine sched{wc.lr, wc.lr * wc.final_lr_ratio, wc.warmup_steps, total};
  WorldInfo info{cfg, ds.grid_h(), ds.grid_w(), ds.codebook_size(), vocab};
  info.text_encoder = encoder;
  {
    int64_t steps = 0, with = 0;
    for (size_t e : train_eps) {
      const auto& a = ds.actions(e);
      for (size_t t = 0; t + 1 < a.size(); t += 2, ++steps) with += !std::isnan(a[t]) || !std::isnan(a[t + 1]);
    }
    info.action_share = steps ? double(with) / double(steps) : 0.0;
    if (with == 0)
      note(fmt::format("no actions in {}: the model learns no action conditioning, and gaia generate will refuse "
                       "--steer / --speed / --actions with it (give the drives signals, or estimate them from the video: "
                       "gaia ingest --motion video, gaia data motion)", opt.tokens.string()));
  }

  fs::path ckpt = opt.out / "checkpoint";
  int step = 0;
  if (train::has_checkpoint(ckpt)) {
    auto st = train::load_checkpoint(ckpt, {{"world", model.ptr().get()}}, {{"world", &optim.to_load()}});
    optim.loaded();
    step = st.step;
    result.resumed = true;
    note(fmt::format("resumed from {} at step {}", ckpt.string(), step));
  } else if (init) {
    // Fresh optimiser and schedule. Action MLPs the --init model lacks start at zero output (model.cpp), so a
    // linear-action model fine-tunes into one with world.action_mlp > 0 from where it was.
    const auto dropped = train::init_from(
        *model, *init, opt.init,
        [](const std::string& k) { return k.rfind("speed_mlp.", 0) == 0 || k.rfind("curvature_mlp.", 0) == 0; },
        [&](const std::string& k) {
          return fresh_text && (k.rfind("word_embedding.", 0) == 0 || k.rfind("text_proj.", 0) == 0);
        });
    note("initialised from " + opt.init.string());
    if (!dropped.empty()) note(dropped);
  }
  init = nullptr;
  // The teacher of distillation: same token grid and codebook. It reads text as it was trained to: this run's
  // batches when they carry its text, else its own words of the same captions (a model learning another text
  // encoder keeps the text behaviour of one trained on words), drawn with the same windows and masks.
  WorldModel teacher{nullptr};
  text::Vocab teacher_vocab;
  std::optional<WorldConfig> teacher_words;  // set: the teacher's batches carry its own words (its m)
  if (!opt.distill_from.empty()) {
    if (!(opt.distill_weight > 0 && std::isfinite(opt.distill_weight)))
      fail("--distill-weight must be a positive number, got {}", opt.distill_weight);
    WorldInfo ti;
    teacher = load_world(opt.distill_from, dev, &ti);
    if (ti.grid_h != ds.grid_h() || ti.grid_w != ds.grid_w() || ti.K != ds.codebook_size())
      fail("{}: a {}x{} token grid with K = {}, but {} has {}x{} with K = {}", opt.distill_from.string(), ti.grid_h,
           ti.grid_w, ti.K, opt.tokens.string(), ds.grid_h(), ds.grid_w(), ds.codebook_size());
    if (ti.embeds_text() && ti.text_encoder != info.text_encoder)
      fail("{}: reads text embeddings of {}, but this run's batches carry {} (distil from weights that read the "
           "built-in words or this run's embeddings)", opt.distill_from.string(), ti.text_encoder,
           info.embeds_text() ? "embeddings of " + info.text_encoder : std::string("words"));
    if (!ti.embeds_text() && (!(ti.vocab == vocab) || info.embeds_text())) {
      if (ti.vocab.size() <= 2 || !ds.has_captions())
        fail("{}: its text vocabulary differs from this run's, and {} (distil from the --init weights, or weights "
             "with their vocabulary)", opt.distill_from.string(),
             ds.has_captions() ? "it has no words" : opt.tokens.string() + " has no captions to give it its own");
      teacher_vocab = ti.vocab;
      teacher_words = wc;
      teacher_words->text_tokens = ti.config.world.text_tokens;
      note(fmt::format("text: {} reads its own words of the captions ({} words)", opt.distill_from.string(),
                       ti.vocab.size()));
    }
    // Its prediction as the run's model would make it: the same copy logit (a calibrated teacher carries its own).
    teacher->cfg.copy_bias = wc.copy_bias;
    teacher->cfg.copy_bias_run = wc.copy_bias_run;
    teacher->eval();
    for (auto& p : teacher->parameters()) p.set_requires_grad(false);
    note("distilling text-only and unconditional predictions from " + opt.distill_from.string());
    if (opt.distill_other_text) {
      if (!ds.has_captions()) fail("--distill-other-text: {} has no captions", opt.tokens.string());
      note("... and text-conditioned predictions under other examples' captions");
    }
  } else if (opt.distill_other_text || opt.distill_procedural_only) {
    fail("{} needs --distill-from (the weights whose predictions it keeps)",
         opt.distill_other_text ? "--distill-other-text" : "--distill-procedural-only");
  }
  if (main) fs::create_directories(opt.out);
  train::StepLoop loop(main ? opt.out / "metrics.jsonl" : fs::path(), step, total, cfg.run.checkpoint_every,
                       opt.stop_after);
  // The copy bias of the last validation (opt.calibrate), written with every weights file; training runs without it.
  CopyBias fitted = CopyBias::of(wc);
  auto set_copy_bias = [&](const CopyBias& c) {
    model->cfg.copy_bias = info.config.world.copy_bias = c.bias;
    model->cfg.copy_bias_run = info.config.world.copy_bias_run = c.run;
  };
  auto save_calibrated = [&](const fs::path& path) {
    set_copy_bias(fitted);
    save_world(model, info, path);
    set_copy_bias(CopyBias::of(wc));
  };
  auto save = [&]() {
    auto& state = optim.gathered();  // every rank: a sharded state comes together on rank 0
    if (main) {
      train::save_checkpoint(ckpt, {{"world", model.ptr().get()}}, {{"world", &state}}, {step, {{"config", cfg.name}}});
      save_calibrated(opt.out / "latest.safetensors");  // usable weights so far (gaia world eval, generate)
    }
    optim.release();
  };
  // The best validation so far (OUT/best.safetensors + OUT/best.json, kept across resumes): on a small dataset the
  // last step has often memorised the training drives, and the best held-out score came earlier.
  const fs::path best_json = opt.out / "best.json";
  double best_bits = std::numeric_limits<double>::infinity();
  if (!result.resumed && main) {  // a fresh run: an older run's best is not this one's
    fs::remove(best_json);
    fs::remove(opt.out / "best.safetensors");
  }
  if (fs::exists(best_json)) best_bits = read_json(best_json).value("bits_per_token", best_bits);
  auto keep_if_best = [&](const nlohmann::json& v) {
    if (!v.contains("bits_per_token")) return;
    const double b = v["bits_per_token"].get<double>();
    if (!(b < best_bits)) return;
    best_bits = b;
    save_calibrated(opt.out / "best.safetensors");  // weights first: best.json never names weights not there
    write_file_atomic(best_json, nlohmann::json({{"step", step}, {"bits_per_token", b}}).dump(2) + "\n");
    result.best_step = step;
  };
  auto validate = [&]() {
    nlohmann::json v;
    if (val_windows.empty()) return v;
    for (auto [name, mode] : {std::pair{"action", Conditioning::kAction}, std::pair{"text", Conditioning::kText},
                              std::pair{"uncond", Conditioning::kUnconditional}}) {
      ScoreOptions so;
      so.mode = mode;
      so.batch = wc.batch_size;
      auto s = score(model, ds, val_windows, text, so);
      v[name] = s.nats;
    }
    v["bits_per_token"] = v["action"].get<double>() / std::log(2.0);
    if (!calibration.empty()) {
      std::vector<CopyCalibration> fits;
      for (const auto& windows : calibration) {
        fits.push_back(calibrate_copy_bias(model, ds, windows, text, ConditioningMix::from(wc), wc.batch_size));
        if (!fits.back().fitted) {  // tokens that never (or always) repeat a frame's: nothing to fit, now or later
          note(fmt::format("copy calibration off: {} of the {} tokens with a previous frame in view repeat it",
                           fits.back().copy_rate > 0 ? "all" : "none", calibration.size() == 2 ? "held-out" : "training"));
          calibration.clear();
          model->train();
          return v;
        }
      }
      ScoreOptions so;
      so.batch = wc.batch_size;
      double nats = 0, bias = 0, run = 0;
      int64_t tokens = 0, fitted_on = 0;
      for (size_t h = 0; h < fits.size(); ++h) {
        const auto& other = fits[fits.size() - 1 - h];  // the other half's (one set: its own)
        model->cfg.copy_bias = other.bias, model->cfg.copy_bias_run = other.run;
        const auto s = score(model, ds, fits.size() == 2 ? calibration[h] : val_windows, text, so);
        nats += s.nats * double(s.tokens), tokens += s.tokens;
        bias += fits[h].bias * double(fits[h].tokens), run += fits[h].run * double(fits[h].tokens);
        fitted_on += fits[h].tokens;
      }
      const double on = double(std::max<int64_t>(fitted_on, 1));
      fitted = {bias / on, run / on};  // what the weights carry
      v["bits_per_token_uncalibrated"] = v["bits_per_token"];
      v["bits_per_token"] = nats / double(std::max<int64_t>(tokens, 1)) / std::log(2.0);
      v["copy_bias"] = fitted.bias;
      v["copy_bias_run"] = fitted.run;
      model->cfg.copy_bias = wc.copy_bias, model->cfg.copy_bias_run = wc.copy_bias_run;
    }
    model->train();
    return v;
  };

  const Precision precision = precision_for(cfg.run.precision, dev, note);
  cfg.run.precision = to_string(precision);  // what runs: the memory plan below counts it
  LossScaler scaler(precision);
  const int64_t tokens_per_batch = int64_t(wc.batch_size) * model->layout.length();
  model->train();
  // The peak this run reaches above what it holds now (the weights, the data), against gaia plan's figure for the
  // same settings: measured on a fresh run of the whole model without a teacher, which the plan describes, where
  // the model lives in this process's memory (the CPU).
  const bool measure_memory = step == 0 && !teacher && opt.train_only.empty() && main && dev.is_cpu();
  const double resident_at_start = sizing::resident_bytes();
  double peak_resident = 0;  // after each step until the first validation (whose batch differs)
  bool validated = false;
  while (step < total) {
    auto t0 = std::chrono::steady_clock::now();
    // The whole step's batch on every rank; each takes its own micro-batches of it.
    auto whole = training_batch(ds, sampler, text, wc, cfg.run.seed, step);
    const auto teacher_whole =
        teacher_words ? training_batch(ds, sampler, TextSource(&teacher_vocab), *teacher_words, cfg.run.seed, step)
                      : whole;
    const double lr = sched(step);
    optim.set_lr(lr);
    optim.zero_grad();
    double lv = 0, kl = teacher ? 0 : -1, kl_other = opt.distill_other_text ? 0 : -1;
    for (int k = 0; k < accumulate; ++k) {
      const int64_t b0 = opt.parallel.micro_offset(wc.batch_size, k);
      auto batch = whole.examples(b0, b0 + micro).to(dev);
      const auto teacher_batch = teacher_words ? teacher_whole.examples(b0, b0 + micro).to(dev) : batch;
      torch::manual_seed(train::step_seed(cfg.run.seed, step, 1 + opt.parallel.micro_stream(k)));
      torch::Tensor loss;
      {
        Autocast autocast(precision, dev);
        auto logits = model->forward(batch);
        loss = image_token_loss(logits, batch.tokens);
        lv += loss.item<double>() / accumulate;  // logged: the cross-entropy alone, comparable with runs without a teacher
        // The KL term to the teacher, which reads b (the batch with the teacher's text), on the examples `keep`,
        // added to the loss; returns its value.
        auto distil = [&](const WorldBatch& b, const torch::Tensor& student, const torch::Tensor& keep) {
          torch::Tensor tl;
          {
            torch::NoGradGuard no_grad;
            tl = teacher->forward(b);
          }
          auto d = image_token_kl(student.to(torch::kFloat), tl.to(torch::kFloat), keep);
          const double v = d.item<double>();
          if (!std::isfinite(v))
            fail("world model training diverged at step {} (the distillation term is not finite)", step);
          loss = loss + opt.distill_weight * d;
          return v;
        };
        // A batch of action-conditioned examples only has nothing to distil: no teacher pass for it.
        auto distilled = [&](const torch::Tensor& keep) {
          return opt.distill_procedural_only ? keep.logical_and(batch.procedural.slice(0, 0, keep.size(0))) : keep;
        };
        const auto keep = distilled(batch.use_action.logical_not());
        if (teacher && keep.any().item<bool>()) kl += distil(teacher_batch, logits, keep) / accumulate;
        if (teacher && opt.distill_other_text) {
          // Half the batch is enough to cover the contradicting prompts, at about half a step's cost.
          const int64_t half = std::max<int64_t>(1, batch.batch() / 2);
          auto other = batch.with_rolled_text(half);
          const auto keep_other = distilled(other.use_text);
          if (keep_other.any().item<bool>())
            kl_other += distil(teacher_batch.with_rolled_text(half), model->forward(other), keep_other) / accumulate;
        }
      }
      // Equal micro-batches: the mean of their mean losses is the whole batch's. fp16 scales the loss.
      const double factor = scaler.scale() / accumulate;
      optim.backward(factor != 1 ? loss * factor : loss, k, accumulate);
    }
    // Logged over the whole batch: the ranks' means averaged.
    lv = dist.sum(lv) / dist.size();
    if (kl >= 0) kl = dist.sum(kl) / dist.size();
    if (kl_other >= 0) kl_other = dist.sum(kl_other) / dist.size();
    if (!std::isfinite(lv)) fail("world model training diverged at step {} (loss is not finite)", step);
    const double gn = optim.step(wc.grad_clip, scaler.scale());
    if (measure_memory && !validated) peak_resident = sizing::peak_resident_bytes();
    const bool skipped = !scaler.update(std::isfinite(gn));  // an overflow: no update this step
    if (skipped && !scaler.active())
      fail("world model training diverged at step {} (the gradient is not finite)", step);
    ++step;
    WorldStepLog log;
    log.step = step;
    log.total = total;
    log.lr = lr;
    log.loss = lv;
    log.grad_norm = gn;
    log.distill = kl;
    log.distill_other = kl_other;
    log.tokens_per_s = double(tokens_per_batch) /
                       std::max(1e-9, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    if (main && loop.validate_now(step, val_every)) {
      validated = true;
      log.validation = true;
      log.val = validate();
      result.last_val = log.val;
      keep_if_best(log.val);
    }
    nlohmann::json record = nlohmann::json({{"step", step}, {"lr", lr}, {"loss", lv}, {"grad_norm", gn},
                               {"tokens_per_s", log.tokens_per_s}, {"val", log.val}});
    if (teacher) record["distill"] = kl;
    if (scaler.active()) {
      record["loss_scale"] = scaler.scale();
      record["skipped"] = skipped;
    }
    if (kl_other >= 0) record["distill_other"] = kl_other;
    if (on_step && main) on_step(log);
    if (loop.end_step(step, record, save)) break;
  }
  result.final_step = step;
  result.best_bits = best_bits;
  if (measure_memory && peak_resident > 0 && resident_at_start > 0) {
    const auto settings = sizing::train_memory_settings(cfg, dist.size(), accumulate, opt.parallel.shard_optimizer,
                                                        TORCH_VERSION_MAJOR >= 2, opt.parallel.shard_gradients);
    const auto plan = sizing::world_train_memory(cfg, settings);
    result.peak_memory_beyond_start = peak_resident - resident_at_start;
    result.planned_memory_beyond_weights = plan.beyond_weights();
    note(fmt::format("memory: the peak was {:.0f} MB above the start of training; gaia plan puts it at {:.0f} MB "
                     "beyond the weights (micro-batch {}, {}, {} attention)",
                     result.peak_memory_beyond_start / 1e6, plan.beyond_weights() / 1e6, settings.micro_batch,
                     cfg.run.precision, settings.fused_attention ? "fused" : "unfused"));
  }
  if (main && fs::exists(best_json)) result.best_step = read_json(best_json).value("step", -1);
  if (main && step >= total) save_calibrated(opt.out / "world.safetensors");
  return result;
}

}  // namespace gaia::world
