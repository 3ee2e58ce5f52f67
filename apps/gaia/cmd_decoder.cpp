// gaia decoder train|eval and gaia decode: the video diffusion decoder of §2.4 (tokens -> 25 Hz video, §5.2).
#include <cstdio>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common.h"
#include "gaia/emerging/common.h"
#include "gaia/core/error.h"
#include "gaia/core/npy.h"
#include "gaia/core/progress.h"
#include "gaia/core/safetensors.h"
#include "gaia/data/gif.h"
#include "gaia/data/video_io.h"
#include "gaia/decoder/evaluate.h"
#include "gaia/decoder/io.h"
#include "gaia/decoder/pipeline.h"
#include "gaia/decoder/trainer.h"
#include "gaia/decoder/video.h"
#include "gaia/synth/synth.h"
#include "gaia/tokenizer/io.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/batch.h"
#include "gaia/world/io.h"
#include "gaia/world/rollout.h"

namespace gaia::app {

namespace {

// [F, M, 3, H, W] in [-1, 1] -> M frames with the futures side by side.
std::vector<int> parse_steps(const std::string& s) {
  std::vector<int> out;
  size_t i = 0;
  while (i < s.size()) {
    size_t j = s.find(',', i);
    if (j == std::string::npos) j = s.size();
    try {
      out.push_back(std::stoi(s.substr(i, j - i)));
    } catch (const std::exception&) {
      fail("--steps: '{}' is not a comma-separated list of integers", s);
    }
    if (out.back() < 1) fail("--steps: step counts must be >= 1");
    i = j + 1;
  }
  if (out.empty()) fail("--steps: empty list");
  return out;
}

}  // namespace

void register_decoder(CLI::App& app) {
  auto* dec = app.add_subcommand("decoder", "video diffusion decoder (§2.4): train, eval");
  dec->require_subcommand(1);
  {
    auto* cmd = dec->add_subcommand("train", "train the video decoder on a dataset (resumes from OUT/checkpoint)");
    auto flags = std::make_shared<SharedFlags>();
    auto o = std::make_shared<decoder::DecoderTrainOptions>();
    auto dataset = std::make_shared<std::string>(), tok = std::make_shared<std::string>();
    cmd->add_option("DATASET", *dataset, "episode dataset (gaia synth / gaia ingest)")->required();
    add_weights_flag(cmd, Weights::Tokenizer, tok.get(), "frozen; gives the conditioning tokens")->required();
    cmd->add_option("--steps", o->steps, "total steps (default: config decoder.steps)")->check(number_in({1, 1e9}));
    cmd->add_option("--init", o->init, "start from these video decoder weights (fine-tuning; ignored when resuming)");
    cmd->add_option("--val-every", o->val_every, "steps between validations (0 = only at the end)");
    cmd->add_option("--stop-after", o->stop_after, "stop after this many steps of this run (checkpointed)")->check(number_in({1, 1e9}));
    add_shared_flags(cmd, flags.get(), "run directory (checkpoint/, decoder.safetensors, metrics.jsonl)");
    auto par = std::make_shared<ParallelFlags>();
    add_parallel_flags(cmd, par.get());
    cmd->callback([=] {
      Config c = resolve_config(*flags);
      if (flags->out.empty()) fail("gaia decoder train: --out RUN_DIR is required");
      if (launch_local_ranks(*par)) return;
      auto dist = join_job(*par, c);
      decoder::DecoderTrainOptions opt = *o;
      opt.parallel = parallel_of(*par, dist.get());
      opt.dataset = *dataset;
      opt.tokenizer = *tok;
      opt.out = flags->out;
      std::unique_ptr<ProgressBar> bar;
      auto r = decoder::train_decoder(
          c, opt,
          [&](const decoder::DecoderStepLog& l) {
            if (!bar) bar = std::make_unique<ProgressBar>(l.total, "decoder", true, l.step);  // a resumed run starts mid-way
            std::string info = fmt::format("loss {:.4f} {:.1f} s/step {}", l.loss, l.seconds, l.task);
            if (l.validation && !l.val.empty())
              info += fmt::format(" | val {:.4f} x0 PSNR {:.1f} dB", l.val.value("loss", 0.0), l.val.value("x0_psnr", 0.0));
            bar->update(l.step, info);
          },
          [](const std::string& n) { std::fprintf(stderr, "decoder: %s\n", n.c_str()); });
      if (bar) bar->finish();
      if (!dist->is_main()) return;
      const int total = opt.steps > 0 ? opt.steps : c.decoder.steps;
      std::printf("decoder: step %d%s; last validation %s\n", r.final_step,
                  r.final_step >= total ? " (done)" : " (checkpointed)", r.last_val.dump().c_str());
    });
  }
  {
    auto* cmd = dec->add_subcommand("eval", "PSNR and flicker of the video decoder vs the tokenizer's decoder on held-out clips");
    auto flags = std::make_shared<SharedFlags>();
    auto dataset = std::make_shared<std::string>(), tok = std::make_shared<std::string>(),
         weights = std::make_shared<std::string>(), steps = std::make_shared<std::string>("50,20,10");
    auto eo = std::make_shared<decoder::DecoderEvalOptions>();
    cmd->add_option("DATASET", *dataset, "episode dataset (its validation episodes are decoded)")->required();
    add_weights_flag(cmd, Weights::Decoder, weights.get())->required();
    add_weights_flag(cmd, Weights::Tokenizer, tok.get())->required();
    cmd->add_option("--clips", eo->clips, "held-out clips")->check(number_in({1, 1e6}));
    auto footage = std::make_shared<std::string>();
    add_footage_flag(cmd, "--footage", footage.get(), "which held-out drives the clips come from");
    cmd->add_option("--token-frames", eo->token_frames, "token frames (6.25 Hz) per clip")->check(number_in({2, 1e6}));
    cmd->add_option("--steps", *steps, "DDIM step counts to compare, e.g. 50,20,10");
    cmd->add_option("--token-fps", eo->token_fps,
                    "rate of the tokens the video decoder gets: 6.25 (the world model's; upsampled to 25 Hz), 12.5, "
                    "or 25 (every frame's own, as the tokenizer decoder gets them)");
    auto world_path = std::make_shared<std::string>();
    auto prompt_frames = std::make_shared<int>(3);
    add_weights_flag(cmd, Weights::World, world_path.get(),
                     "decode its rollouts instead of the true tokens: the clip's first --prompt-frames token frames and "
                     "its recorded actions prompt it (top-k 50, no guidance), both decoders decode what it generates");
    cmd->add_option("--prompt-frames", *prompt_frames, "with --world: true token frames before the generated ones")
        ->needs(cmd->get_option("--world"));
    add_shared_flags(cmd, flags.get(), "output directory (eval.json)");
    cmd->callback([=] {
      Config run = resolve_config(*flags);
      apply_threads(run);
      if (flags->out.empty()) fail("gaia decoder eval: --out DIR is required");
      if (!world_path->empty() && (*prompt_frames < 1 || *prompt_frames >= eo->token_frames))
        fail("gaia decoder eval: --prompt-frames must be in [1, --token-frames - 1] = [1, {}], got {}",
             eo->token_frames - 1, *prompt_frames);
      auto dev = parse_device(run.run.device);
      Config dc;
      auto model = decoder::load_decoder(*weights, dev, &dc);
      apply_sampling_sets(*flags, "decoder", kDecoderSamplingKeys, *weights, dc);
      auto t = tokenizer::load_tokenizer(*tok, dev);
      if (t->cfg.codebook_size != model->K || t->cfg.downsample != model->D)
        fail("{}: the decoder was trained with K = {}, D = {}; this tokenizer has K = {}, D = {}", *tok, model->K,
             model->D, t->cfg.codebook_size, t->cfg.downsample);
      decoder::DecoderEvalOptions o = *eo;
      o.footage = world::parse_footage(*footage);
      o.steps = parse_steps(*steps);
      o.seed = uint64_t(run.run.seed);
      o.precision = run_precision(run, dev, "decoder eval");
      world::WorldModel wm{nullptr};
      if (!world_path->empty()) {
        world::WorldInfo info;
        wm = world::load_world(*world_path, dev, &info);
        emerging::check_tokenizer_fits(info, *world_path, t, *tok);
        auto clip_no = std::make_shared<uint64_t>(0);
        const int64_t P = *prompt_frames;
        o.generate = [wm, P, clip_no, seed = o.seed](const torch::Tensor& tokens, const torch::Tensor& actions) {
          const int64_t N = tokens.size(0), h = tokens.size(1), w = tokens.size(2);
          world::RolloutPrompt p;
          p.tokens = tokens.slice(0, 0, P).reshape({P, h * w});
          auto a = actions.clone();  // the world model's action inputs are normalised (batch.h)
          a.select(1, 0).div_(world::kSpeedScale);
          a.select(1, 1).div_(world::kCurvatureScale);
          p.actions = a;
          world::RolloutOptions ro;  // the paper's sampling: top-k, k = 50 (§5.1); no guidance
          ro.frames = int(N - P);
          ro.seed = seed + (*clip_no)++;  // each clip its own draw, the same on every run
          auto m = wm;
          return world::rollout(m, p, ro).tokens[0].view({N, h, w});
        };
      }
      std::unique_ptr<ProgressBar> bar;
      auto j = decoder::evaluate_decoder(dc, model, t, *dataset, o, [&](int d, int total) {
        // Made at the first report, which comes after a window's work: rate and ETA count from there.
        if (!bar) bar = std::make_unique<ProgressBar>(total, "decoder eval (DDIM steps)", true, d);
        bar->update(d);
      });
      if (bar) bar->finish();
      if (!world_path->empty()) j["world"] = {{"weights", *world_path}, {"prompt_frames", *prompt_frames}};
      fs::create_directories(flags->out);
      write_file_atomic(fs::path(flags->out) / "eval.json", j.dump(2) + "\n");
      std::printf("%s\n", j.dump(2).c_str());
    });
  }
}

void register_decode(CLI::App& app) {
  auto* cmd = app.add_subcommand("decode", "tokens -> video (MP4, GIF, PNG contact sheet) with the video decoder (§5.2)");
  auto flags = std::make_shared<SharedFlags>();
  auto tokens = std::make_shared<std::string>(), tok = std::make_shared<std::string>(),
       weights = std::make_shared<std::string>();
  auto fast = std::make_shared<bool>(false);
  auto steps = std::make_shared<int>(0);
  auto fps = std::make_shared<double>(25.0), token_fps = std::make_shared<double>(6.25);
  cmd->add_option("TOKENS", *tokens, "rollout.safetensors (gaia generate), tokens .npy [N, h, w], or a token episode dir")
      ->required();
  add_weights_flag(cmd, Weights::Tokenizer, tok.get(), "its decoder for --fast and the video decoder's conditioning")
      ->required();
  auto* decoder_opt = add_weights_flag(cmd, Weights::Decoder, weights.get());
  cmd->add_flag("--fast", *fast, "decode frame by frame with the tokenizer's decoder (a quick preview)")
      ->excludes(decoder_opt);
  cmd->add_option("--ddim-steps", *steps, "DDIM steps (default: the decoder's config, paper §5.2: 50)")
      ->check(key_range("decoder.ddim_steps"));
  cmd->add_option("--fps", *fps, "output frame rate: 6.25, 12.5 or 25 (temporal upsampling, §5.2)");
  cmd->add_option("--token-fps", *token_fps, "frame rate of the token frames");
  add_shared_flags(cmd, flags.get(), "output video path (.mp4; a .gif and a .png contact sheet are written beside it)");
  cmd->callback([=] {
    Config run = resolve_config(*flags);
    apply_threads(run);
    if (flags->out.empty()) fail("gaia decode: --out VIDEO.mp4 is required");
    if (!*fast && weights->empty()) fail("gaia decode: give --decoder WEIGHTS, or --fast for the tokenizer's decoder");
    auto dev = parse_device(run.run.device);
    auto t = tokenizer::load_tokenizer(*tok, dev);
    auto ids = read_tokens(*tokens);  // [F, N, h, w]
    const int64_t F = ids.size(0), N = ids.size(1), gh = t->height / t->cfg.downsample, gw = t->width / t->cfg.downsample;
    if (ids.size(2) != gh || ids.size(3) != gw)
      fail("{}: token grid {}x{} does not match the tokenizer's {}x{} ({}x{} frames, D = {})", *tokens, ids.size(2),
           ids.size(3), gh, gw, t->height, t->width, t->cfg.downsample);
    if (ids.min().item<int64_t>() < 0 || ids.max().item<int64_t>() >= t->cfg.codebook_size)
      fail("{}: token ids must be in [0, {}) (the tokenizer's codebook)", *tokens, t->cfg.codebook_size);
    // The tokenizer's decoding of every token frame: the --fast output, and the video decoder's conditioning.
    auto cond = decoder::coarse_frames(t, ids, dev);  // [F, N, 3, H, W]
    const Precision precision = run_precision(run, dev, "decode");
    torch::Tensor video;
    double out_fps = *token_fps;
    if (*fast) {
      video = cond;
    } else {
      std::unique_ptr<ProgressBar> bar;  // the window count is known once the decoder's config is read
      video = decoder::diffusion_decode(t, *weights, ids, cond, *steps, *token_fps, *fps, uint64_t(run.run.seed), dev,
                                        [&](int d, int total) {
                                          if (!bar) bar = std::make_unique<ProgressBar>(total, "decode", true, d);
                                          bar->update(d);
                                        },
                                        [&](Config& dc) { apply_sampling_sets(*flags, "decoder", kDecoderSamplingKeys, *weights, dc); },
                                        precision);
      if (bar) bar->finish();
      out_fps = *fps;
    }
    auto frames = decoder::side_by_side(video);
    fs::path out = flags->out;
    if (out.has_parent_path()) fs::create_directories(out.parent_path());
    fs::path gif = fs::path(out).replace_extension(".gif"), png = fs::path(out).replace_extension(".png");
    std::vector<cv::Mat> sheet;
    std::vector<std::string> labels;
    const size_t every = std::max<size_t>(1, frames.size() / 12);
    for (size_t k = 0; k < frames.size(); k += every) {
      sheet.push_back(frames[k]);
      labels.push_back(fmt::format("{:.2f} s", double(k) / out_fps));
    }
    // The three files are one output: when one cannot be written (a full disk), the ones before it go too.
    std::vector<fs::path> written;
    try {
      data::write_video(out, frames, out_fps);
      written.push_back(out);
      data::write_gif(gif, frames, out_fps);
      written.push_back(gif);
      data::write_png(png, synth::contact_sheet(sheet, labels, 4, std::min(512, frames[0].cols)));
    } catch (...) {
      std::error_code ec;
      for (auto& w : written) fs::remove(w, ec);
      throw;
    }
    std::printf("decoded %lld token frames x %lld futures -> %zu frames at %g Hz (%s): %s, %s, %s\n", (long long)N,
                (long long)F, frames.size(), out_fps, *fast ? "tokenizer decoder" : "video decoder", out.c_str(),
                gif.c_str(), png.c_str());
  });
}

}  // namespace gaia::app
