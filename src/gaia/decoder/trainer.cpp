#include "gaia/decoder/trainer.h"

#include <chrono>
#include <cmath>
#include <fstream>
#include <map>

#include "gaia/core/error.h"
#include "gaia/data/clip_sampler.h"
#include "gaia/data/geofence.h"
#include "gaia/decoder/evaluate.h"
#include "gaia/decoder/io.h"
#include "gaia/eval/metrics.h"
#include "gaia/sizing/sizing.h"
#include "gaia/tokenizer/io.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/checkpoint.h"
#include "gaia/train/ema.h"
#include "gaia/train/optim.h"
#include "gaia/train/parallel_adamw.h"
#include "gaia/train/schedule.h"
#include "gaia/train/step_loop.h"

namespace gaia::decoder {

namespace F = torch::nn::functional;

Clips load_clips(const std::vector<std::unique_ptr<data::Episode>>& episodes, const std::vector<ClipRef>& refs,
                 tokenizer::ImageTokenizer& tok, bool with_cond, const torch::Device& dev) {
  if (refs.empty() || refs.front().frames.empty()) fail("decoder: no clip frames to load");
  torch::NoGradGuard ng;
  std::vector<torch::Tensor> xs;
  for (const auto& r : refs)
    for (int64_t i : r.frames) {
      cv::Mat f = episodes.at(r.episode)->frame_bgr(i);
      if (f.rows != tok->height || f.cols != tok->width)
        fail("{}: frames are {}x{}, the tokenizer works at {}x{}", episodes[r.episode]->dir().string(), f.rows, f.cols,
             tok->height, tok->width);
      xs.push_back(tokenizer::image_to_tensor(f.data, f.rows, f.cols));
    }
  const int64_t B = int64_t(refs.size()), T = int64_t(refs.at(0).frames.size());
  auto x = torch::stack(xs).to(dev);  // [B*T, 3, H, W]
  Clips c;
  c.frames = x.view({B, T, 3, x.size(2), x.size(3)});
  auto ids = tok->tokenize(x);        // [B*T, h, w]
  c.tokens = ids.view({B, T, ids.size(1), ids.size(2)});
  if (with_cond) c.cond = tok->decode_tokens(ids).clamp(-1, 1).view_as(c.frames);
  return c;
}

TaskBatch make_task_batch(const Clips& clips, const FrameMasks& masks, int rate, double t, double token_dropout,
                          const NoiseSchedule& sched, int64_t K, int64_t D, bool interp_base) {
  const auto& x = clips.frames;
  const int64_t B = x.size(0), T = x.size(1), h = clips.tokens.size(2), w = clips.tokens.size(3);
  auto dev = x.device();
  std::vector<float> ctx_v(masks.context.begin(), masks.context.end()), tok_v(masks.tokens.begin(), masks.tokens.end());
  auto ctx = torch::tensor(ctx_v).to(dev).view({1, T}).expand({B, T}).contiguous();  // [B, T]
  auto has_tok = torch::tensor(tok_v).to(dev).view({1, T, 1, 1});                    // [1, T, 1, 1]
  auto keep = (torch::rand({B, T, h, w}, x.options()) >= token_dropout).to(x.dtype()) * has_tok;  // [B, T, h, w]
  TaskBatch b;
  b.input.tokens = torch::where(keep > 0, clips.tokens, torch::full_like(clips.tokens, K));
  if (clips.cond.defined()) {
    auto keep_px = keep.repeat_interleave(D, 2).repeat_interleave(D, 3).unsqueeze(2);  // [B, T, 1, H, W]
    b.input.cond_image = clips.cond * keep_px;
    if (interp_base)  // the interpolate task's in-between frames: the blend of their context neighbours
      b.input.cond_image = interpolation_base(b.input.cond_image, x, ctx, has_tok.view({1, T}).expand({B, T}) > 0);
  }
  auto tt = torch::full({B, T}, t, x.options());
  auto time = tt * (1 - ctx);  // context frames are clean: time 0
  auto alpha = sched.alpha(time).view({B, T, 1, 1, 1}), sigma = sched.sigma(time).view({B, T, 1, 1, 1});
  auto eps = torch::randn_like(x);
  auto c5 = ctx.view({B, T, 1, 1, 1});
  const auto r = x - coarse_base(b.input.cond_image, x);  // what is diffused (the frame itself without cond_image)
  b.input.x = c5 * r + (1 - c5) * add_noise(r, eps, alpha, sigma);
  b.input.context = ctx;
  b.input.time = time;
  b.input.rate = torch::full({B}, rate, torch::TensorOptions().dtype(torch::kLong).device(dev));
  b.input.temporal = masks.temporal;
  b.v_true = v_target(r, eps, alpha, sigma);
  b.weight = 1 - ctx;
  return b;
}

namespace {

struct ClipPool {
  std::vector<std::unique_ptr<data::Episode>> episodes;
  std::vector<std::vector<ClipRef>> by_rate;  // [3] clips at 6.25, 12.5, 25 Hz
};

ClipPool make_pool(const data::Dataset& ds, const std::vector<size_t>& eps, int T, bool all_rates) {
  ClipPool p;
  std::map<size_t, size_t> pos;
  for (size_t e : eps) {
    pos[e] = p.episodes.size();
    p.episodes.push_back(std::make_unique<data::Episode>(ds.episode(e)));
  }
  p.by_rate.resize(3);
  for (int r = 0; r < (all_rates ? 3 : 1); ++r)
    for (auto& c : data::enumerate_clips(ds, eps, T, kRates[r], 0.5))
      p.by_rate[size_t(r)].push_back({pos.at(c.episode), c.frames});
  return p;
}

}  // namespace

DecoderTrainResult train_decoder(const Config& cfg, const DecoderTrainOptions& opt,
                                 const std::function<void(const DecoderStepLog&)>& on_step,
                                 const std::function<void(const std::string&)>& on_note) {
  const auto& dc = cfg.decoder;
  const torch::Device dev = parse_device(cfg.run.device);
  DecoderTrainResult result;
  train::Distributed& dist = opt.parallel.job();
  const bool main = dist.is_main();
  auto note = [&](const std::string& s) {
    if (on_note && main) on_note(s);
  };
  const int accumulate = opt.parallel.accumulate;
  const int64_t micro = opt.parallel.micro_batch(dc.batch_size, "decoder.batch_size");
  // Weights, gradients, AdamW's two moments and the EMA copy in float32, before any of it is allocated.
  sizing::check_memory(20.0 * double(sizing::decoder_params(cfg).total), "training this video decoder (decoder.*)");
  // One run per --out; a checkpoint a kill broke is put back (by rank 0, before any rank reads it).
  const auto run_dir = train::claim_run_dir(opt.out, dist, note);
  auto tok = tokenizer::load_tokenizer(opt.tokenizer, dev);
  for (auto& p : tok->parameters()) p.set_requires_grad(false);
  const int64_t K = tok->cfg.codebook_size, D = tok->cfg.downsample;
  if (tok->height != cfg.data.height || tok->width != cfg.data.width)
    fail("{}: the tokenizer works at {}x{}, the config's data size is {}x{}", opt.tokenizer.string(), tok->height,
         tok->width, cfg.data.height, cfg.data.width);

  data::Dataset ds(opt.dataset);
  data::Split split = data::load_or_default_split(ds, data::kDefaultValFraction, cfg.run.seed);
  auto val_ids = split.held_out();
  const int T = dc.frames;
  ClipPool train = make_pool(ds, data::episode_indices(ds, split.train), T, true);
  for (int r = 0; r < 3; ++r)
    if (train.by_rate[size_t(r)].empty())
      fail("{}: no training clip of {} frames at {} Hz (decoder.frames); episodes are too short", opt.dataset.string(),
           T, kRates[r]);
  ClipPool val = make_pool(ds, data::episode_indices(ds, val_ids), T, false);
  std::vector<ClipRef> val_refs;
  if (!val.by_rate[0].empty()) {
    const size_t n = val.by_rate[0].size(), k = std::min<size_t>(size_t(opt.val_clips), n);
    for (size_t i = 0; i < k; ++i) val_refs.push_back(val.by_rate[0][i * n / k]);  // spread over the held-out set
  } else {
    note("no validation clips (no held-out episode long enough): validation skipped");
  }

  torch::manual_seed(cfg.run.seed);
  VideoUNet model(dc, K, D), ema(dc, K, D);
  model->to(dev);
  ema->to(dev);
  train::ema_copy(*ema, *model);
  train::ParallelAdamW optim(model->parameters(), {dc.lr, dc.weight_decay, dc.beta1, dc.beta2}, opt.parallel);
  const int total = opt.steps > 0 ? opt.steps : dc.steps;
  train::WarmupCosine sched{dc.lr, dc.final_lr, dc.warmup_steps, total};
  NoiseSchedule noise{-15.0, 15.0, dc.schedule_shift};
  note(fmt::format("3D U-Net with {:.2f}M parameters, K = {}, D = {}, T' = {}", model->parameter_count() / 1e6, K, D, T));

  fs::path ckpt = opt.out / "checkpoint";
  int step = 0;
  if (train::has_checkpoint(ckpt)) {
    auto st = train::load_checkpoint(ckpt, {{"decoder", model.ptr().get()}, {"ema", ema.ptr().get()}},
                                     {{"decoder", &optim.to_load()}});
    optim.loaded();
    step = st.step;
    result.resumed = true;
    note(fmt::format("resumed from {} at step {}", ckpt.string(), step));
  } else if (!opt.init.empty()) {
    // Same architecture required (init_from names the file on a mismatch), except that temporal attention layers
    // the --init weights lack (decoder.temporal_levels grown, e.g. to full resolution as in Ho et al.) start fresh:
    // their output projection is zero, so the fine-tuned network starts as the given one. Fresh optimiser and schedule.
    const auto dropped = train::init_from(*model, *load_decoder(opt.init, dev), opt.init,
                                          [](const std::string& k) { return k.find(".temporal.") != std::string::npos; });
    train::ema_copy(*ema, *model);
    note("initialised from " + opt.init.string());
    if (!dropped.empty()) note(dropped);
  }
  if (main) fs::create_directories(opt.out);
  train::StepLoop loop(main ? opt.out / "metrics.jsonl" : fs::path(), step, total, cfg.run.checkpoint_every,
                       opt.stop_after);
  auto save = [&]() {
    auto& state = optim.gathered();  // every rank: a sharded state comes together on rank 0
    if (main) {
      train::save_checkpoint(ckpt, {{"decoder", model.ptr().get()}, {"ema", ema.ptr().get()}}, {{"decoder", &state}},
                             {step, {{"config", cfg.name}}});
      save_decoder(ema, cfg, opt.out / "latest.safetensors");  // usable EMA weights so far (gaia decode, decoder eval)
    }
    optim.release();
  };
  // Validation: v loss of the EMA weights on fixed held-out clips (video task, 6.25 Hz) at t' = 0.25, 0.5, 0.75
  // of the trained range (decoder.train_max_time) with fixed noise, and the PSNR of the one-step estimate x_hat at
  // its middle.
  auto validate = [&]() {
    nlohmann::json v;
    if (val_refs.empty()) return v;
    torch::NoGradGuard ng;
    ema->eval();
    auto clips = load_clips(val.episodes, val_refs, tok, dc.cond_image, dev);
    double loss = 0, psnr = 0;
    for (double f : {0.25, 0.5, 0.75}) {
      const double t = f * dc.train_max_time;
      torch::manual_seed(cfg.run.seed + 12345);
      auto b = make_task_batch(clips, task_masks(Task::kVideo, T), 0, t, 0.0, noise, K, D, dc.interp_base);
      auto vp = ema->forward(b.input);
      loss += v_loss(vp, b.v_true, b.weight, dc.w_l1, dc.w_l2).item<double>() / 3;
      if (f == 0.5) {
        auto tt = torch::full({1}, t, vp.options().dtype(torch::kFloat));
        auto x_hat = x_from_v(b.input.x, vp, noise.alpha(tt), noise.sigma(tt)) + coarse_base(b.input.cond_image, clips.frames);
        psnr = psnr_pm1(x_hat, clips.frames);
      }
    }
    v["loss"] = loss;
    v["x0_psnr"] = psnr;  // PSNR of the one-step estimate of x0 in the middle of the trained range
    return v;
  };

  const Precision precision = precision_for(cfg.run.precision, dev, note);
  LossScaler scaler(precision);
  model->train();
  while (step < total) {
    auto t0 = std::chrono::steady_clock::now();
    std::mt19937_64 rng(train::step_seed(cfg.run.seed, step));
    torch::manual_seed(train::step_seed(cfg.run.seed, step, 1));
    auto draw = draw_task(rng);
    const auto& pool = train.by_rate[size_t(draw.rate)];
    std::vector<ClipRef> refs;
    std::uniform_int_distribution<size_t> pick(0, pool.size() - 1);
    for (int i = 0; i < dc.batch_size; ++i) refs.push_back(pool[pick(rng)]);
    const double t = std::uniform_real_distribution<double>(0.0, dc.train_max_time)(rng);
    const double lr = sched(step);
    optim.set_lr(lr);
    optim.zero_grad();
    double lv = 0;
    // This rank's micro-batches of the step's clips: only those are loaded and encoded.
    for (int k = 0; k < accumulate; ++k) {
      const int64_t b0 = opt.parallel.micro_offset(dc.batch_size, k);
      std::vector<ClipRef> mine(refs.begin() + b0, refs.begin() + b0 + micro);
      if (accumulate > 1 || dist.size() > 1)
        torch::manual_seed(train::step_seed(cfg.run.seed, step, 1 + opt.parallel.micro_stream(k)));
      auto clips = load_clips(train.episodes, mine, tok, dc.cond_image, dev);
      auto b = make_task_batch(clips, task_masks(draw.task, T), draw.rate, t, dc.token_dropout, noise, K, D,
                               dc.interp_base);
      torch::Tensor loss;
      {
        Autocast autocast(precision, dev);
        auto v_pred = model->forward(b.input).to(torch::kFloat);
        loss = v_loss(v_pred, b.v_true, b.weight, dc.w_l1, dc.w_l2);
        if (dc.w_temporal > 0) loss = loss + dc.w_temporal * temporal_v_loss(v_pred, b.v_true, b.weight);
      }
      lv += loss.item<double>() / accumulate;
      const double factor = scaler.scale() / accumulate;  // fp16 scales the loss
      optim.backward(factor != 1 ? loss * factor : loss, k, accumulate);
    }
    lv = dist.sum(lv) / dist.size();
    if (!std::isfinite(lv)) fail("video decoder training diverged at step {} (loss is not finite)", step);
    const double gn = optim.step(dc.grad_clip, scaler.scale());
    if (!scaler.update(std::isfinite(gn)) && !scaler.active())
      fail("video decoder training diverged at step {} (the gradient is not finite)", step);
    train::ema_update(*ema, *model, dc.ema_decay, step);
    ++step;
    DecoderStepLog log;
    log.step = step;
    log.total = total;
    log.lr = lr;
    log.loss = lv;
    log.grad_norm = gn;
    log.task = to_string(draw.task) + "@" + fmt::format("{}Hz", kRates[draw.rate]);
    log.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (main && loop.validate_now(step, opt.val_every)) {
      log.validation = true;
      log.val = validate();
      result.last_val = log.val;
    }
    const nlohmann::json record = nlohmann::json({{"step", step}, {"lr", lr}, {"loss", lv}, {"grad_norm", gn}, {"task", log.task},
                               {"t", t}, {"seconds", log.seconds}, {"val", log.val}});
    if (on_step && main) on_step(log);
    if (loop.end_step(step, record, save)) break;
  }
  result.final_step = step;
  if (main && step >= total) save_decoder(ema, cfg, opt.out / "decoder.safetensors");
  return result;
}

}  // namespace gaia::decoder
