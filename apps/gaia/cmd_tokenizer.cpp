// gaia tokenizer train|eval|reconstruct|pca and gaia tokenize: the image tokenizer of §2.2.
#include <cstdio>
#include <random>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/data/frame_set.h"
#include "gaia/data/geofence.h"
#include "gaia/data/video_io.h"
#include "gaia/tokenizer/evaluate.h"
#include "gaia/tokenizer/io.h"
#include "gaia/tokenizer/tokenize.h"
#include "gaia/tokenizer/trainer.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::app {

namespace {

// Frames from a dataset (its validation episodes first, or all) or a video file, resized to the tokenizer size.
std::vector<cv::Mat> load_frames(const std::string& src, int h, int w, int max_frames, int stride) {
  std::vector<cv::Mat> frames;
  if (fs::exists(fs::path(src) / "dataset.json")) {
    data::Dataset ds(src);
    for (size_t e : data::episode_indices(ds, data::held_out_ids(ds, 0))) {
      data::Episode ep = ds.episode(e);
      for (int64_t i = 0; i < ep.size() && static_cast<int>(frames.size()) < max_frames; i += stride)
        frames.push_back(data::resize_center_crop(ep.frame_bgr(i), h, w));
    }
  } else {
    data::VideoSource v(src);
    data::VideoFrame f;
    for (int i = 0; v.next(&f) && static_cast<int>(frames.size()) < max_frames; ++i)
      if (i % stride == 0) frames.push_back(data::resize_center_crop(f.bgr, h, w));
  }
  if (frames.empty()) fail("{}: no frames", src);
  return frames;
}

// The shared preamble of the commands that use trained weights: run config, threads, device, the tokenizer and
// the config it was trained with (stored in its weights file).
struct Loaded {
  torch::Device device{torch::kCPU};
  Config config;  // the tokenizer's own config
  tokenizer::ImageTokenizer model{nullptr};
};

Loaded open_tokenizer(const SharedFlags& flags, const std::string& weights) {
  Config run = resolve_config(flags);
  apply_threads(run);
  Loaded l;
  l.device = parse_device(run.run.device);
  l.model = tokenizer::load_tokenizer(weights, l.device, &l.config, flags.config.empty() ? nullptr : &run);
  return l;
}

}  // namespace

void register_tokenizer(CLI::App& app) {
  auto* tok = app.add_subcommand("tokenizer", "image tokenizer (§2.2): train, eval, reconstruct, pca");
  tok->require_subcommand(1);

  {
    auto* cmd = tok->add_subcommand("train", "train the VQ tokenizer on a dataset (resumes from OUT/checkpoint)");
    auto flags = std::make_shared<SharedFlags>();
    auto o = std::make_shared<tokenizer::TrainOptions>();
    auto dataset = std::make_shared<std::string>();
    auto vgg = std::make_shared<std::string>(), dino = std::make_shared<std::string>();
    cmd->add_option("DATASET", *dataset, "episode dataset (gaia synth / gaia ingest)")->required();
    cmd->add_option("--vgg", *vgg, "VGG16 weights (torchvision layout, safetensors) for the perceptual loss");
    cmd->add_option("--dino", *dino, "DINO ViT weights (timm or torchvision layout, safetensors) for the DINO loss");
    cmd->add_option("--init", o->init, "start from these tokenizer weights (fine-tuning; ignored when resuming); "
                    "without --config, their architecture (tokenizer.* keys not given with --set) is kept");
    cmd->add_option("--steps", o->steps, "total steps (default: config tokenizer.steps)")->check(number_in({1, 1e9}));
    cmd->add_option("--val-every", o->val_every, "steps between validations (0 = only at the end)");
    cmd->add_option("--stop-after", o->stop_after, "stop after this many steps of this run (checkpointed)")->check(number_in({1, 1e9}));
    cmd->add_flag("--decoder-only", o->decoder_only,
                  "train only the decoder (needs --init): encoder and codebook frozen, so every frame keeps its codes "
                  "and token datasets made with the --init weights stay valid");
    add_shared_flags(cmd, flags.get(), "run directory (checkpoint/, tokenizer.safetensors, metrics.jsonl)");
    auto par = std::make_shared<ParallelFlags>();
    add_parallel_flags(cmd, par.get());
    cmd->callback([=] {
      Config c = resolve_config(*flags);
      if (flags->out.empty()) fail("gaia tokenizer train: --out RUN_DIR is required");
      if (launch_local_ranks(*par)) return;
      auto dist = join_job(*par, c);
      tokenizer::TrainOptions opt = *o;
      opt.parallel = parallel_of(*par, dist.get());
      opt.dataset = *dataset;
      opt.out = flags->out;
      if (!opt.init.empty())
        for (const auto& k : adopt_init_architecture(c, opt.init, *flags, "tokenizer"))
          if (dist->is_main()) std::fprintf(stderr, "tokenizer: %s, as the --init weights have it\n", k.c_str());
      opt.vgg = *vgg;
      opt.dino = *dino;
      std::unique_ptr<ProgressBar> bar;
      auto r = tokenizer::train_tokenizer(
          c, opt,
          [&](const tokenizer::StepLog& l) {
            if (!bar) bar = std::make_unique<ProgressBar>(l.total, "tokenizer", true, l.step);  // a resumed run starts mid-way
            std::string info = fmt::format("loss {:.4f} l1 {:.4f}", l.losses.value("loss", 0.0), l.losses.value("l1", 0.0));
            if (l.validation && !l.val.empty())
              info += fmt::format(" | val psnr {:.2f} usage {:.0f}%", l.val.value("psnr", 0.0), 100 * l.val.value("usage", 0.0));
            bar->update(l.step, info);
          },
          [](const std::string& n) { std::fprintf(stderr, "tokenizer: %s\n", n.c_str()); });
      if (bar) bar->finish();
      if (!dist->is_main()) return;
      std::printf("tokenizer: step %d%s; last validation %s\n", r.final_step,
                  r.final_step >= (opt.steps > 0 ? opt.steps : c.tokenizer.steps) ? " (done)" : " (checkpointed)",
                  r.last_val.dump().c_str());
    });
  }

  {
    auto* cmd = tok->add_subcommand("eval", "PSNR, SSIM, code usage, perplexity and bit compression on held-out frames");
    auto flags = std::make_shared<SharedFlags>();
    auto src = std::make_shared<std::string>(), weights = std::make_shared<std::string>();
    auto max_frames = std::make_shared<int>(256);
    auto stride = std::make_shared<int>(5);
    cmd->add_option("SOURCE", *src, "dataset (its validation episodes) or a video file")->required();
    add_weights_flag(cmd, Weights::Tokenizer, weights.get())->required();
    cmd->add_option("--max-frames", *max_frames, "frames to score")->check(number_in({1, 1e9}));
    cmd->add_option("--stride", *stride, "video: use every Nth frame (a dataset's frames are spread evenly over its held-out episodes)")
        ->check(number_in({1, 1e6}));
    add_shared_flags(cmd, flags.get(), "JSON file for the metrics (optional)", WithPrecision::kNo);
    cmd->callback([=] {
      auto [dev, c, t] = open_tokenizer(*flags, *weights);
      std::vector<cv::Mat> frames;
      std::vector<tokenizer::FrameTags> tags;
      if (fs::exists(fs::path(*src) / "dataset.json")) {
        // Spread over every held-out episode (so over every weather and time of day), not the first few drives.
        data::Dataset ds(*src);
        auto set = data::held_out_frames(ds, c.run.seed, 0, std::max(1, *max_frames));
        for (const auto& f : set.frames) {
          const data::Episode& ep = *set.episodes[f.episode];
          frames.push_back(data::resize_center_crop(ep.frame_bgr(f.frame), c.data.height, c.data.width));
          const auto& m = ep.meta();
          const auto road = m.extra.find("road");
          tags.push_back({{"weather", m.weather}, {"time_of_day", m.time_of_day},
                          {"road", road == m.extra.end() ? "" : road->second}, {"episode", m.id},
                          {"footage", m.is_procedural() ? "procedural" : "real"}});
        }
      } else {
        frames = load_frames(*src, c.data.height, c.data.width, *max_frames, *stride);
      }
      ProgressBar bar(static_cast<int64_t>(frames.size()), "eval");
      auto j = tokenizer::evaluate_reconstruction(t, c, frames, tags, dev, [&](int64_t n) { bar.update(n); });
      bar.finish();
      j["source"] = *src;
      std::printf("%s\n", j.dump(2).c_str());
      if (!flags->out.empty()) write_file_atomic(flags->out, j.dump(2) + "\n");
    });
  }

  {
    auto* cmd = tok->add_subcommand("reconstruct", "side-by-side original | reconstruction video (MP4) and PNG sheet");
    auto flags = std::make_shared<SharedFlags>();
    auto src = std::make_shared<std::string>(), weights = std::make_shared<std::string>();
    auto max_frames = std::make_shared<int>(100);
    cmd->add_option("SOURCE", *src, "video file or dataset")->required();
    add_weights_flag(cmd, Weights::Tokenizer, weights.get())->required();
    cmd->add_option("--max-frames", *max_frames, "frames to reconstruct")->check(number_in({1, 1e9}));
    add_shared_flags(cmd, flags.get(), "output directory", WithPrecision::kNo);
    cmd->callback([=] {
      if (flags->out.empty()) fail("gaia tokenizer reconstruct: --out DIR is required");
      auto [dev, c, t] = open_tokenizer(*flags, *weights);
      auto frames = load_frames(*src, c.data.height, c.data.width, *max_frames, 1);
      auto rec = tokenizer::decode_tokens(t, tokenizer::encode_frames(t, frames, dev), dev);
      std::vector<cv::Mat> side;
      for (size_t i = 0; i < frames.size(); ++i) {
        cv::Mat s;
        cv::hconcat(frames[i], rec[i], s);
        side.push_back(s);
      }
      fs::create_directories(flags->out);
      data::write_video(fs::path(flags->out) / "reconstruction.mp4", side, 25.0);
      std::vector<cv::Mat> sheet_rows(side.begin(), side.begin() + static_cast<long>(std::min<size_t>(side.size(), 6)));
      cv::Mat sheet;
      cv::vconcat(sheet_rows, sheet);
      data::write_png(fs::path(flags->out) / "reconstruction.png", sheet);
      std::printf("wrote %s/reconstruction.mp4 and reconstruction.png (%zu frames)\n", flags->out.c_str(), frames.size());
    });
  }

  {
    auto* cmd = tok->add_subcommand("pca", "top-3 PCA components of the token embeddings as RGB (the paper's Fig. 3)");
    auto flags = std::make_shared<SharedFlags>();
    auto src = std::make_shared<std::string>(), weights = std::make_shared<std::string>();
    auto n = std::make_shared<int>(6);
    cmd->add_option("SOURCE", *src, "video file or dataset")->required();
    add_weights_flag(cmd, Weights::Tokenizer, weights.get())->required();
    cmd->add_option("--frames", *n, "frames to show")->check(number_in({1, 1e6}));
    add_shared_flags(cmd, flags.get(), "output PNG (default: pca.png)", WithPrecision::kNo);
    cmd->callback([=] {
      auto [dev, c, t] = open_tokenizer(*flags, *weights);
      auto frames = load_frames(*src, c.data.height, c.data.width, *n, 10);
      cv::Mat sheet = tokenizer::pca_sheet(t, frames, dev);
      fs::path out = flags->out.empty() ? fs::path("pca.png") : fs::path(flags->out);
      data::write_png(out, sheet);
      std::printf("wrote %s\n", out.c_str());
    });
  }

  {
    auto* cmd = app.add_subcommand("tokenize", "frames -> token episodes at the world-model rate (resumes per episode)");
    auto flags = std::make_shared<SharedFlags>();
    auto src = std::make_shared<std::string>(), weights = std::make_shared<std::string>();
    cmd->add_option("DATASET", *src, "episode dataset")->required();
    add_weights_flag(cmd, Weights::Tokenizer, weights.get())->required();
    auto mirror = std::make_shared<bool>(false);
    cmd->add_flag("--mirror", *mirror,
                  "also write each episode in mirror image as <id>-mirror (flipped frames, negated curvature, left/right "
                  "swapped in captions): balances left and right steering");
    add_shared_flags(cmd, flags.get(), "token dataset directory", WithPrecision::kNo);
    cmd->callback([=] {
      Config run = resolve_config(*flags);
      apply_threads(run);
      if (flags->out.empty()) fail("gaia tokenize: --out TOKENS is required");
      auto dev = parse_device(run.run.device);
      std::unique_ptr<ProgressBar> bar;
      auto r = tokenizer::tokenize_dataset(*src, *weights, flags->out, run.data.world_fps, dev,
                                           [&](int64_t done, int64_t total) {
                                             if (!bar) bar = std::make_unique<ProgressBar>(total, "tokenize");
                                             bar->update(done);
                                           },
                                           *mirror);
      if (bar) bar->finish();
      std::printf("tokenized %lld episodes (%lld skipped as already done), %lld steps at %.4g Hz -> %s\n",
                  (long long)r.episodes_written, (long long)r.episodes_skipped, (long long)r.steps, run.data.world_fps,
                  flags->out.c_str());
    });
  }
}

}  // namespace gaia::app
