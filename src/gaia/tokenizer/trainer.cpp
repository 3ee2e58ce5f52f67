#include "gaia/tokenizer/trainer.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/data/frame_sampler.h"
#include "gaia/data/geofence.h"
#include "gaia/eval/metrics.h"
#include "gaia/sizing/sizing.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/tokenizer/discriminator.h"
#include "gaia/tokenizer/io.h"
#include "gaia/tokenizer/teachers.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/checkpoint.h"
#include "gaia/train/ema.h"
#include "gaia/train/optim.h"
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
  auto note = [&](const std::string& s) {
    result.notes.push_back(s);
    if (on_note) on_note(s);
  };
  // Weights, gradients and AdamW's two moments in float32 (tokenizer and discriminator), before any is allocated.
  sizing::check_memory(16.0 * double(sizing::tokenizer_params(cfg).total + sizing::discriminator_params(cfg)),
                     "training this tokenizer (tokenizer.*)");
  train::RunDir run_dir(opt.out, note);  // one run per --out; a checkpoint a kill broke is put back

  data::Dataset ds(opt.dataset);
  data::Split split = data::load_or_default_split(ds, 0.1, cfg.run.seed);
  auto train_eps = data::episode_indices(ds, split.train);
  auto val_ids = split.held_out();
  auto val_eps = data::episode_indices(ds, val_ids);
  data::FrameSampler train(ds, train_eps, cfg.data.height, cfg.data.width, cfg.data.balance_tokenizer,
                           cfg.data.balance_exponent, cfg.data.balance_bins);
  std::unique_ptr<data::FrameSampler> val;
  if (!val_eps.empty())
    val = std::make_unique<data::FrameSampler>(ds, val_eps, cfg.data.height, cfg.data.width, std::vector<std::string>{}, 0.0, 1);
  else note("no validation episodes (dataset too small): validation skipped");

  // Teachers: real weights or the loss is off, never a stand-in.
  std::unique_ptr<Vgg16> vgg;
  std::unique_ptr<DinoViT> dino;
  if (!opt.vgg.empty() && fs::exists(opt.vgg)) vgg = std::make_unique<Vgg16>(opt.vgg);
  else note(opt.vgg.empty() ? "no VGG16 teacher given (--vgg): perceptual loss off"
                            : "VGG16 teacher " + opt.vgg.string() + " not found: perceptual loss off");
  if (opt.decoder_only) {
    if (!opt.dino.empty()) note("--decoder-only: the codes are frozen, DINO distillation loss off (teacher not loaded)");
  } else if (!opt.dino.empty() && fs::exists(opt.dino)) dino = std::make_unique<DinoViT>(opt.dino);
  else note(opt.dino.empty() ? "no DINO teacher given (--dino): DINO distillation loss off"
                             : "DINO teacher " + opt.dino.string() + " not found: DINO distillation loss off");
  if (vgg) (*vgg)->to(dev);
  if (dino) (*dino)->to(dev);

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
  auto opt_g = train::make_adamw(opt.decoder_only ? model->decoder->parameters() : model->parameters(), tc.lr, tc.weight_decay, tc.beta1, tc.beta2);
  auto opt_d = train::make_adamw(disc->parameters(), tc.lr, tc.weight_decay, tc.beta1, tc.beta2);
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
    auto st = train::load_checkpoint(ckpt, modules, {{"tokenizer", opt_g.get()}, {"discriminator", opt_d.get()}});
    step = st.step;
    usage = st.extra.value("usage", usage);
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
  fs::create_directories(opt.out);
  train::StepLoop loop(opt.out / "metrics.jsonl", step, total, cfg.run.checkpoint_every, opt.stop_after);

  auto save = [&]() {
    nlohmann::json extra = {{"usage", usage}, {"config", cfg.name}};
    std::vector<std::pair<std::string, const torch::nn::Module*>> out(modules.begin(), modules.end());
    train::save_checkpoint(ckpt, out, {{"tokenizer", opt_g.get()}, {"discriminator", opt_d.get()}}, {step, extra});
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

  model->train();
  disc->train();
  std::vector<torch::Tensor> recent_codes;
  while (step < total) {
    std::mt19937_64 rng(train::step_seed(cfg.run.seed, step));
    torch::manual_seed(train::step_seed(cfg.run.seed, step, 1));
    auto x = batch_tensor(train, train.sample(static_cast<size_t>(tc.batch_size), rng), dev);
    double lr = sched(step);
    train::set_lr(*opt_g, lr);
    train::set_lr(*opt_d, lr);

    auto o = model->forward(x);
    auto l1 = (o.reconstruction - x).abs().mean();
    auto l2 = (o.reconstruction - x).pow(2).mean();
    auto loss = tc.w_l1 * l1 + tc.w_l2 * l2;
    if (!opt.decoder_only) loss = loss + tc.w_codebook * (o.q.codebook_loss + tc.commitment * o.q.commit_loss);
    nlohmann::json terms = {{"l1", l1.item<double>()}, {"l2", l2.item<double>()},
                            {"codebook", o.q.codebook_loss.item<double>()}};
    if (vgg) {
      auto lp = perceptual_loss(*vgg, o.reconstruction, x);
      loss = loss + tc.w_perceptual * lp;
      terms["perceptual"] = lp.item<double>();
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
      terms["dino"] = ld.item<double>();
    }
    const bool gan = step >= tc.disc_start && tc.w_gan > 0;
    if (gan) {
      auto lg = hinge_g_loss(disc->forward(o.reconstruction));
      double w = tc.w_gan;
      if (tc.gan_adaptive) {
        // VQGAN: ||d loss_rec / d W_last|| / ||d loss_gan / d W_last||, W_last = the decoder's output convolution.
        auto last = model->decoder->conv_out->weight;
        auto g_rec = torch::autograd::grad({loss}, {last}, {}, /*retain_graph=*/true)[0];
        auto g_gan = torch::autograd::grad({lg}, {last}, {}, /*retain_graph=*/true)[0];
        double lambda = std::clamp(g_rec.norm().item<double>() / (g_gan.norm().item<double>() + 1e-4), 0.0, 1e4);
        w *= lambda;
        terms["gan_weight"] = w;
      }
      loss = loss + w * lg;
      terms["gan_g"] = lg.item<double>();
    }
    if (!std::isfinite(loss.item<double>())) fail("tokenizer training diverged at step {} (loss is not finite)", step);
    opt_g->zero_grad();
    loss.backward();
    opt_g->step();
    if (gan) {
      auto ld = hinge_d_loss(disc->forward(x), disc->forward(o.reconstruction.detach()));
      opt_d->zero_grad();
      ld.backward();
      opt_d->step();
      terms["gan_d"] = ld.item<double>();
    }
    terms["loss"] = loss.item<double>();

    // Code usage since the last restart; unused codes are re-seeded from recent encoder outputs.
    {
      auto idx = o.q.indices.reshape({-1}).to(torch::kCPU);
      auto acc = idx.accessor<int64_t, 1>();
      for (int64_t i = 0; i < idx.size(0); ++i) usage[static_cast<size_t>(acc[i])]++;
    }
    if (averaged) train::ema_update(*averaged->decoder, *model->decoder, tc.ema_decay, step);
    ++step;
    if (opt.restart_every > 0 && !opt.decoder_only && step % opt.restart_every == 0 && step < total) {
      torch::NoGradGuard ng;
      auto ze = F::normalize(model->quantizer->proj_in(model->encoder->forward(x).permute({0, 2, 3, 1}).reshape({-1, tc.z_channels})),
                             F::NormalizeFuncOptions().dim(1));
      auto u = torch::tensor(usage, torch::kLong).to(dev);
      auto gen = at::detail::createCPUGenerator(train::step_seed(cfg.run.seed, step, 2));
      int64_t n = model->quantizer->restart_dead_codes(u.to(torch::kCPU), ze.to(torch::kCPU), gen);
      terms["restarted_codes"] = n;
      std::fill(usage.begin(), usage.end(), 0);
    }

    StepLog log;
    log.step = step;
    log.total = total;
    log.lr = lr;
    log.losses = terms;
    if (loop.validate_now(step, opt.val_every)) {
      log.validation = true;
      log.val = validate();
      result.last_val = log.val;
    }
    const nlohmann::json record = nlohmann::json({{"step", step}, {"lr", lr}, {"losses", terms}, {"val", log.val}});
    if (on_step) on_step(log);
    if (loop.end_step(step, record, save)) break;
  }
  result.final_step = step;
  if (step >= total) save_tokenizer(final_model(), cfg, opt.out / "tokenizer.safetensors");
  return result;
}

}  // namespace gaia::tokenizer
