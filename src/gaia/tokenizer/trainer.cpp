#include "gaia/tokenizer/trainer.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <optional>
#include <random>

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/data/frame_sampler.h"
#include "gaia/data/geofence.h"
#include "gaia/eval/metrics.h"
#include "gaia/sizing/sizing.h"
#include "gaia/tokenizer/augment.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/tokenizer/discriminator.h"
#include "gaia/tokenizer/io.h"
#include "gaia/tokenizer/teachers.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/checkpoint.h"
#include "gaia/train/ema.h"
#include "gaia/train/optim.h"
#include "gaia/train/parallel_adamw.h"
#include "gaia/train/schedule.h"
#include "gaia/train/step_loop.h"

namespace gaia::tokenizer {

namespace F = torch::nn::functional;

namespace {

torch::Tensor batch_tensor(const data::FrameSampler& s, const std::vector<std::pair<size_t, int64_t>>& picks,
                           const torch::Device& dev) {
  std::vector<torch::Tensor> xs;
  for (auto& [e, i] : picks) {
    cv::Mat f = s.frame(e, i);
    xs.push_back(image_to_tensor(f.data, f.rows, f.cols));
  }
  return torch::stack(xs).to(dev);
}

}  // namespace

TrainResult train_tokenizer(const Config& cfg, const TrainOptions& opt, const std::function<void(const StepLog&)>& on_step,
                            const std::function<void(const std::string&)>& on_note) {
  const auto& tc = cfg.tokenizer;
  const torch::Device dev = parse_device(cfg.run.device);
  TrainResult result;
  train::Distributed& dist = opt.parallel.job();
  const bool main = dist.is_main();
  auto note = [&](const std::string& s) {
    result.notes.push_back(s);
    if (on_note && main) on_note(s);
  };
  const int accumulate = opt.parallel.accumulate;
  const int64_t micro = opt.parallel.micro_batch(tc.batch_size, "tokenizer.batch_size");
  // Weights, gradients and AdamW's two moments in float32 (tokenizer and discriminator), before any is allocated.
  sizing::check_memory(16.0 * double(sizing::tokenizer_params(cfg).total + sizing::discriminator_params(cfg)),
                     "training this tokenizer (tokenizer.*)");
  // Teachers: real weights or the loss is off, never a stand-in. A file the caller names must exist: a mistyped
  // --vgg / --dino is an error naming it (before the run directory is touched), not a run without that loss.
  std::unique_ptr<Vgg16> vgg;
  std::unique_ptr<DinoViT> dino;
  if (!opt.vgg.empty()) vgg = std::make_unique<Vgg16>(opt.vgg);  // throws naming a missing or mismatched file
  else note("no VGG16 teacher given (--vgg): perceptual loss off");
  if (opt.decoder_only) {
    if (!opt.dino.empty()) {
      if (!fs::exists(opt.dino)) fail("{}: no such DINO ViT weights file", opt.dino.string());
      note("--decoder-only: the codes are frozen, DINO distillation loss off (teacher not loaded)");
    }
  } else if (!opt.dino.empty()) dino = std::make_unique<DinoViT>(opt.dino);
  else note("no DINO teacher given (--dino): DINO distillation loss off");
  if (vgg) (*vgg)->to(dev);
  if (dino) (*dino)->to(dev);
  // One run per --out; a checkpoint a kill broke is put back (by rank 0, before any rank reads it).
  const auto run_dir = train::claim_run_dir(opt.out, dist, note);

  data::Dataset ds(opt.dataset);
  data::Split split = data::load_or_default_split(ds, data::kDefaultValFraction, cfg.run.seed);
  auto train_eps = data::episode_indices(ds, split.train);
  auto val_ids = split.held_out();
  auto val_eps = data::episode_indices(ds, val_ids);
  data::FrameSampler train(ds, train_eps, cfg.data.height, cfg.data.width, cfg.data.balance_tokenizer,
                           cfg.data.balance_exponent, cfg.data.balance_bins);
  std::unique_ptr<data::FrameSampler> val;
  if (!val_eps.empty())
    val = std::make_unique<data::FrameSampler>(ds, val_eps, cfg.data.height, cfg.data.width, std::vector<std::string>{}, 0.0, 1);
  else note("no validation episodes (dataset too small): validation skipped");

  torch::manual_seed(cfg.run.seed);
  ImageTokenizer model(cfg, dino ? (*dino)->dim : 0);
  PatchDiscriminator disc(tc);
  model->to(dev);
  disc->to(dev);
  // With tokenizer.ema_decay > 0, `averaged` holds the EMA of the decoder's weights; its other parts are copied from
  // the trained model whenever it is used, so it encodes exactly as the model does.
  ImageTokenizer averaged{nullptr};
  if (tc.ema_decay > 0) {
    averaged = ImageTokenizer(cfg, dino ? (*dino)->dim : 0);
    averaged->to(dev);
    averaged->eval();
  }
  if (opt.decoder_only) {
    if (opt.init.empty() && !train::has_checkpoint(opt.out / "checkpoint"))
      fail("tokenizer train --decoder-only: needs --init weights (the frozen encoder and codebook to decode)");
    for (auto& p : model->encoder->parameters()) p.set_requires_grad(false);
    for (auto& p : model->quantizer->parameters()) p.set_requires_grad(false);
  }
  const train::AdamWSettings adamw{tc.lr, tc.weight_decay, tc.beta1, tc.beta2};
  train::ParallelAdamW opt_g(opt.decoder_only ? model->decoder->parameters() : model->parameters(), adamw,
                             opt.parallel);
  train::ParallelAdamW opt_d(disc->parameters(), adamw, opt.parallel);
  const int total = opt.steps > 0 ? opt.steps : tc.steps;
  train::WarmupCosine sched{tc.lr, tc.final_lr, tc.warmup_steps, total};

  fs::path ckpt = opt.out / "checkpoint";
  int step = 0;
  std::vector<int64_t> usage(static_cast<size_t>(tc.codebook_size), 0);
  std::vector<std::pair<std::string, torch::nn::Module*>> modules{{"tokenizer", model.ptr().get()},
                                                                   {"discriminator", disc.ptr().get()}};
  // A checkpoint written with ema_decay = 0 has no average to resume: turning the EMA on then starts it afresh.
  bool average_from_here = false;
  if (averaged) {
    average_from_here = train::has_checkpoint(ckpt) && !fs::exists(ckpt / "ema.safetensors");
    if (!average_from_here) modules.emplace_back("ema", averaged.ptr().get());
  }
  if (train::has_checkpoint(ckpt)) {
    auto st = train::load_checkpoint(ckpt, modules,
                                     {{"tokenizer", &opt_g.to_load()}, {"discriminator", &opt_d.to_load()}});
    opt_g.loaded();
    opt_d.loaded();
    step = st.step;
    if (main) usage = st.extra.value("usage", usage);  // the ranks' counts are summed: rank 0 carries the saved ones
    result.resumed = true;
    note(fmt::format("resumed from {} at step {}", ckpt.string(), step));
    if (average_from_here) {
      train::ema_copy(*averaged, *model);
      modules.emplace_back("ema", averaged.ptr().get());  // saved with the next checkpoint
      note(fmt::format("the checkpoint has no weight average (ema_decay was 0): it starts at step {}", step));
    }
  }
  else if (!opt.init.empty()) {
    // Fine-tuning: weights from an earlier run, fresh optimiser and schedule. The architecture must match.
    Config init_cfg;
    auto init = load_tokenizer(opt.init, dev, &init_cfg, &cfg);
    // the DINO head and any refinement or token blocks the --init weights lack start fresh (the blocks as identities)
    const auto dropped = train::init_from(*model, *init, opt.init, [](const std::string& k) {
      return k.rfind("dino_head.", 0) == 0 || k.rfind("decoder.refine.", 0) == 0 || k.rfind("decoder.token.", 0) == 0;
    });
    note("initialised from " + opt.init.string());
    if (!dropped.empty()) note(dropped);
  }
  if (averaged && !result.resumed) train::ema_copy(*averaged, *model);
  if (main) fs::create_directories(opt.out);
  train::StepLoop loop(main ? opt.out / "metrics.jsonl" : fs::path(), step, total, cfg.run.checkpoint_every,
                       opt.stop_after);
  // Code usage over every rank's frames since the last restart.
  auto total_usage = [&]() {
    auto u = torch::tensor(std::vector<double>(usage.begin(), usage.end()), torch::kDouble);
    dist.sum(u);
    return u.to(torch::kLong);
  };
  auto save = [&]() {
    auto u = total_usage();
    auto& g = opt_g.gathered();  // every rank: a sharded state comes together on rank 0
    auto& d = opt_d.gathered();
    if (main) {
      nlohmann::json extra = {{"usage", std::vector<int64_t>(u.data_ptr<int64_t>(), u.data_ptr<int64_t>() + u.numel())},
                              {"config", cfg.name}};
      std::vector<std::pair<std::string, const torch::nn::Module*>> out(modules.begin(), modules.end());
      train::save_checkpoint(ckpt, out, {{"tokenizer", &g}, {"discriminator", &d}}, {step, extra});
    }
    opt_g.release();
    opt_d.release();
  };

  // The tokenizer that is validated and saved: the model, or its decoder average with the model's encoder, codebook
  // and heads.
  auto final_model = [&]() -> ImageTokenizer& {
    if (!averaged) return model;
    auto mine = averaged->named_children();
    for (const auto& c : model->named_children())
      if (c.key() != "decoder") train::ema_copy(*mine[c.key()], *c.value());
    return averaged;
  };

  auto validate = [&]() {
    nlohmann::json v;
    if (!val) return v;
    ImageTokenizer& m = final_model();
    m->eval();
    std::mt19937_64 rng(cfg.run.seed + 12345);  // the same held-out frames every time
    auto picks = val->sample(static_cast<size_t>(opt.val_frames), rng);
    double p = 0, s = 0;
    std::vector<int64_t> counts(static_cast<size_t>(tc.codebook_size), 0);
    {
      torch::NoGradGuard ng;
      auto x = batch_tensor(*val, picks, dev);
      auto o = m->forward(x);
      auto idx = o.q.indices.reshape({-1}).to(torch::kCPU);
      auto acc = idx.accessor<int64_t, 1>();
      for (int64_t i = 0; i < idx.size(0); ++i) counts[static_cast<size_t>(acc[i])]++;
      for (size_t i = 0; i < picks.size(); ++i) {
        cv::Mat rec(cfg.data.height, cfg.data.width, CV_8UC3);
        tensor_to_image(o.reconstruction[static_cast<int64_t>(i)], rec.data);
        cv::Mat orig = val->frame(picks[i].first, picks[i].second);
        p += eval::psnr(orig, rec);
        s += eval::ssim(orig, rec);
      }
    }
    auto cs = eval::code_stats(counts);
    model->train();
    v = {{"psnr", p / double(picks.size())}, {"ssim", s / double(picks.size())}, {"usage", cs.usage},
         {"perplexity", cs.perplexity}};
    return v;
  };

  const Precision precision = precision_for(cfg.run.precision, dev, note);
  LossScaler scaler(precision);
  model->train();
  disc->train();
  std::vector<torch::Tensor> recent_codes;
  while (step < total) {
    std::mt19937_64 rng(train::step_seed(cfg.run.seed, step));
    torch::manual_seed(train::step_seed(cfg.run.seed, step, 1));
    const auto picks = train.sample(static_cast<size_t>(tc.batch_size), rng);
    double lr = sched(step);
    opt_g.set_lr(lr);
    opt_d.set_lr(lr);
    opt_g.zero_grad();
    const bool gan = step >= tc.disc_start && tc.w_gan > 0;
    // This rank's micro-batches of the step's frames; the discriminator's step needs them again after the
    // tokenizer's.
    std::vector<std::pair<torch::Tensor, torch::Tensor>> seen;  // (frames, reconstruction) per micro-batch
    std::map<std::string, double> sums;  // loss terms summed over the micro-batches
    torch::Tensor x;
    for (int k = 0; k < accumulate; ++k) {
      const int64_t b0 = opt.parallel.micro_offset(tc.batch_size, k);
      if (accumulate > 1 || dist.size() > 1)
        torch::manual_seed(train::step_seed(cfg.run.seed, step, 1 + opt.parallel.micro_stream(k)));
      x = darken_some(batch_tensor(train, std::vector<std::pair<size_t, int64_t>>(picks.begin() + b0, picks.begin() + b0 + micro), dev),
                      tc.augment_dark);
      std::optional<Autocast> autocast(std::in_place, precision, dev);  // the forward passes; backward after it
      auto o = model->forward(x);
      auto l1 = (o.reconstruction - x).abs().mean();
      auto l2 = (o.reconstruction - x).pow(2).mean();
      auto loss = tc.w_l1 * l1 + tc.w_l2 * l2;
      if (!opt.decoder_only) loss = loss + tc.w_codebook * (o.q.codebook_loss + tc.commitment * o.q.commit_loss);
      sums["l1"] += l1.item<double>();
      sums["l2"] += l2.item<double>();
      sums["codebook"] += o.q.codebook_loss.item<double>();
      if (vgg) {
        auto lp = perceptual_loss(*vgg, o.reconstruction, x);
        loss = loss + tc.w_perceptual * lp;
        sums["perceptual"] += lp.item<double>();
      }
      if (dino) {
        torch::Tensor target;
        {
          torch::NoGradGuard ng;
          target = (*dino)->forward(x);  // [B, Dd, h', w'] -> resized to the token grid
          target = F::interpolate(target, F::InterpolateFuncOptions()
                                              .size(std::vector<int64_t>{o.q.codes.size(2), o.q.codes.size(3)})
                                              .mode(torch::kBilinear).align_corners(false));
        }
        auto pred = model->dino_head(o.q.codes.permute({0, 2, 3, 1})).permute({0, 3, 1, 2});
        auto ld = (1 - F::cosine_similarity(pred, target, F::CosineSimilarityFuncOptions().dim(1))).mean();
        loss = loss + tc.w_dino * ld;
        sums["dino"] += ld.item<double>();
      }
      torch::Tensor lg;
      if (gan) lg = hinge_g_loss(disc->forward(o.reconstruction));
      autocast.reset();
      if (gan) {
        double w = tc.w_gan;
        if (tc.gan_adaptive) {
          // VQGAN: ||d loss_rec / d W_last|| / ||d loss_gan / d W_last||, W_last = the decoder's output convolution
          // (the gradients averaged over the ranks: on one micro-batch per rank, those of the whole batch).
          auto last = model->decoder->conv_out->weight;
          auto g_rec = torch::autograd::grad({loss}, {last}, {}, /*retain_graph=*/true)[0];
          auto g_gan = torch::autograd::grad({lg}, {last}, {}, /*retain_graph=*/true)[0];
          dist.average(g_rec);
          dist.average(g_gan);
          double lambda = std::clamp(g_rec.norm().item<double>() / (g_gan.norm().item<double>() + 1e-4), 0.0, 1e4);
          w *= lambda;
          sums["gan_weight"] += w;
        }
        loss = loss + w * lg;
        sums["gan_g"] += lg.item<double>();
        seen.emplace_back(x, o.reconstruction.detach());
      }
      sums["loss"] += loss.item<double>();
      const double factor = scaler.scale() / accumulate;  // fp16 scales the loss
      opt_g.backward(factor != 1 ? loss * factor : loss, k, accumulate);
      // Code usage since the last restart; unused codes are re-seeded from recent encoder outputs.
      auto idx = o.q.indices.reshape({-1}).to(torch::kCPU);
      auto acc = idx.accessor<int64_t, 1>();
      for (int64_t i = 0; i < idx.size(0); ++i) usage[static_cast<size_t>(acc[i])]++;
    }
    nlohmann::json terms;
    if (scaler.active()) terms["loss_scale"] = scaler.scale();
    for (const auto& [name, v] : sums) terms[name] = dist.sum(v / accumulate) / dist.size();
    if (!std::isfinite(terms["loss"].get<double>()))
      fail("tokenizer training diverged at step {} (loss is not finite)", step);
    if (!scaler.update(std::isfinite(opt_g.step(-1, scaler.scale())))) terms["skipped"] = true;  // an fp16 overflow
    if (gan) {
      opt_d.zero_grad();
      double d_loss = 0;
      for (size_t k = 0; k < seen.size(); ++k) {
        const auto& [frames, recon] = seen[k];
        torch::Tensor ld;
        {
          Autocast autocast(precision, dev);
          ld = hinge_d_loss(disc->forward(frames), disc->forward(recon));
        }
        d_loss += ld.item<double>() / accumulate;
        const double factor = scaler.scale() / accumulate;
        opt_d.backward(factor != 1 ? ld * factor : ld, int(k), int(seen.size()));
      }
      opt_d.step(-1, scaler.scale());
      terms["gan_d"] = dist.sum(d_loss) / dist.size();
    }
    if (averaged) train::ema_update(*averaged->decoder, *model->decoder, tc.ema_decay, step);
    ++step;
    if (opt.restart_every > 0 && !opt.decoder_only && step % opt.restart_every == 0 && step < total) {
      torch::NoGradGuard ng;
      // Usage over every rank; rank 0 restarts from its frames and sends the codebook to the others.
      auto u = total_usage();
      double n = 0;
      if (main) {
        auto ze = F::normalize(
            model->quantizer->proj_in(model->encoder->forward(x).permute({0, 2, 3, 1}).reshape({-1, tc.z_channels})),
            F::NormalizeFuncOptions().dim(1));
        auto gen = at::detail::createCPUGenerator(train::step_seed(cfg.run.seed, step, 2));
        n = double(model->quantizer->restart_dead_codes(u, ze.to(torch::kCPU), gen));
      }
      if (dist.size() > 1) {
        std::vector<torch::Tensor> codebook;
        for (auto& t : model->quantizer->parameters()) codebook.push_back(t);
        for (auto& t : model->quantizer->buffers()) codebook.push_back(t);
        dist.broadcast(codebook, 0);
      }
      terms["restarted_codes"] = int64_t(dist.sum(n));
      std::fill(usage.begin(), usage.end(), 0);
    }

    StepLog log;
    log.step = step;
    log.total = total;
    log.lr = lr;
    log.losses = terms;
    if (main && loop.validate_now(step, opt.val_every)) {
      log.validation = true;
      log.val = validate();
      result.last_val = log.val;
    }
    const nlohmann::json record = nlohmann::json({{"step", step}, {"lr", lr}, {"losses", terms}, {"val", log.val}});
    if (on_step && main) on_step(log);
    if (loop.end_step(step, record, save)) break;
  }
  result.final_step = step;
  if (main && step >= total) save_tokenizer(final_model(), cfg, opt.out / "tokenizer.safetensors");
  return result;
}

}  // namespace gaia::tokenizer
